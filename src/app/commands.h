// The commands of the mobirt command line that live outside main.cpp. Each takes the arguments
// after the command's name and returns the exit code; errors are thrown as mobirt::Error.
#pragma once

#include <string>
#include <vector>

namespace mobirt {

// mobirt accuracy SCENE [render options] [--json FILE] [--heatmap FILE.png]: the GPU renderer
// against the double-precision reference tracer (src/reference/).
int cmd_accuracy(const std::vector<std::string>& args);

}  // namespace mobirt
