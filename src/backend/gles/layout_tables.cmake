# Writes the GLES backend's name tables from the files that define the names, so that no C++ copy
# of them is kept by hand:
#   binding slots: every `#define MOBIRT_BIND_*` of glsl/layout.h (SAMPLER(MOBIRT_BIND_X, name)
#     lines name them; the backend turns the name into a texture unit);
#   specialisation: every `layout(constant_id = MOBIRT_SPEC_*) const int NAME` of
#     glsl/prelude_vk.glsl (the GLES shaders get `#define NAME value` instead).
# Fails when layout.h has a MOBIRT_SPEC_* that prelude_vk.glsl does not declare, or a NAME that
# prelude_es.glsl gives no default (`#ifndef NAME`).
#   cmake -DGLSL_DIR=glsl -DOUTPUT=gles_layout_tables.h -P layout_tables.cmake
cmake_minimum_required(VERSION 3.25)

file(READ ${GLSL_DIR}/layout.h layout)
file(READ ${GLSL_DIR}/prelude_vk.glsl prelude_vk)
file(READ ${GLSL_DIR}/prelude_es.glsl prelude_es)

set(bindings "")
string(REGEX MATCHALL "#define[ \t]+MOBIRT_BIND_[A-Z0-9_]+" lines "${layout}")
foreach(line ${lines})
  string(REGEX REPLACE "#define[ \t]+" "" name "${line}")
  string(APPEND bindings "    {\"${name}\", ${name}},\n")
endforeach()

set(declared "")
set(defines "")
string(REGEX MATCHALL "layout[ \t]*\\([ \t]*constant_id[ \t]*=[ \t]*MOBIRT_SPEC_[A-Z0-9_]+[ \t]*\\)[ \t]*const[ \t]+int[ \t]+[A-Za-z0-9_]+"
       lines "${prelude_vk}")
foreach(line ${lines})
  string(REGEX MATCH "(MOBIRT_SPEC_[A-Z0-9_]+).*int[ \t]+([A-Za-z0-9_]+)" _ "${line}")
  set(id ${CMAKE_MATCH_1})
  set(name ${CMAKE_MATCH_2})
  if(NOT prelude_es MATCHES "#ifndef[ \t]+${name}[ \t\r\n]")
    message(FATAL_ERROR "layout_tables: ${name} (${id}) has no `#ifndef ${name}` default in glsl/prelude_es.glsl")
  endif()
  list(APPEND declared ${id})
  string(APPEND defines "    {${id}, \"${name}\"},\n")
endforeach()
string(REGEX MATCHALL "#define[ \t]+MOBIRT_SPEC_[A-Z0-9_]+" lines "${layout}")
foreach(line ${lines})
  string(REGEX REPLACE "#define[ \t]+" "" id "${line}")
  if(NOT id IN_LIST declared)
    message(FATAL_ERROR "layout_tables: glsl/layout.h defines ${id} but glsl/prelude_vk.glsl declares no "
                        "layout(constant_id = ${id}) const int NAME")
  endif()
endforeach()

file(WRITE ${OUTPUT}.tmp
"// Generated from glsl/layout.h and glsl/prelude_vk.glsl by src/backend/gles/layout_tables.cmake: do not edit.
#pragma once
#include \"layout.h\"

namespace mobirt::gles {

// MOBIRT_BIND_* by name: the slot a SAMPLER(MOBIRT_BIND_X, name) line means.
struct BindingName {
  const char* name;
  int slot;
};
inline constexpr BindingName kBindingNames[] = {
${bindings}};

// Specialization constant id -> the #define it becomes in a GLSL ES shader.
struct SpecDefine {
  unsigned id;
  const char* define;
};
inline constexpr SpecDefine kSpecDefines[] = {
${defines}};

}  // namespace mobirt::gles
")
# Replaced only when it changed, so that editing a comment in layout.h recompiles nothing more.
file(COPY_FILE ${OUTPUT}.tmp ${OUTPUT} ONLY_IF_DIFFERENT)
file(REMOVE ${OUTPUT}.tmp)
