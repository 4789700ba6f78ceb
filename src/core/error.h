// Errors as values with a kind, so that the CLI maps them to exit codes and tests can tell them
// apart. A user error names the file (or option) and says what to do about it.
#pragma once

#include <stdexcept>
#include <string>

namespace mobirt {

enum class ErrorKind {
  BadInput,      // a file or option the user gave is missing, broken or over a limit (exit 2)
  NoDevice,      // no usable graphics device or driver (exit 2)
  Unsupported,   // the device lacks a feature mobirt needs (exit 2)
  Constraint,    // a pass would break an OpenGL ES 2.0 constraint (a bug in mobirt; exit 1)
  Internal,      // a driver call failed or an invariant broke (exit 1)
};

class Error : public std::runtime_error {
 public:
  Error(ErrorKind kind, const std::string& message) : std::runtime_error(message), kind_(kind) {}
  ErrorKind kind() const { return kind_; }
  int exit_code() const {
    return kind_ == ErrorKind::Constraint || kind_ == ErrorKind::Internal ? 1 : 2;
  }

 private:
  ErrorKind kind_;
};

// "FILE: MESSAGE" errors for bad input.
inline Error input_error(const std::string& file, const std::string& message) {
  return Error(ErrorKind::BadInput, file.empty() ? message : file + ": " + message);
}

}  // namespace mobirt
