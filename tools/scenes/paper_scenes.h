// The three scenes of the MobiRT paper (toasters, marbles, fish), rebuilt from generated meshes and
// procedural textures, and a material library for the real Utah toasters OBJ.
#pragma once

#include <filesystem>

namespace mobirt::scenes {

void make_toaster(const std::filesystem::path& dir);
void make_marbles(const std::filesystem::path& dir);
void make_fish(const std::filesystem::path& dir);
// utah-toasters.mtl for ../shared/scenes/utah-toasters/Toasters004.obj (used with --mtl).
void make_utah_mtl(const std::filesystem::path& dir);

}  // namespace mobirt::scenes
