# Expands the #include "file" lines of a GLSL ES entry file (GLSL ES 1.00 has no #include), so
# that the GLES backend can embed one self-contained source per shader.
#   cmake -DINPUT=glsl/es/trace.frag -DINCLUDE_DIR=glsl -DOUTPUT_GLSL=x.frag -DOUTPUT_HEADER=x.h
#         -DVARIABLE=es_trace_frag -P expand_glsl.cmake
# The header holds `inline constexpr char VARIABLE[] = R"...";`. layout.h's include guard is kept
# (the GLSL preprocessor honours it), so files are expanded every time they are included.
cmake_minimum_required(VERSION 3.25)

function(expand file depth out_var)
  if(depth GREATER 16)
    message(FATAL_ERROR "expand_glsl: #include nesting too deep at ${file}")
  endif()
  file(READ ${file} rest)
  set(rest "\n${rest}")  # so that a directive is always a newline, blanks and #include
  get_filename_component(dir ${file} DIRECTORY)
  set(text "")
  while(TRUE)
    string(REGEX MATCH "\n[ \t]*#[ \t]*include[ \t]+\"([^\"]+)\"" directive "${rest}")
    if(NOT directive)
      break()
    endif()
    set(name ${CMAKE_MATCH_1})
    string(FIND "${rest}" "${directive}" at)
    string(SUBSTRING "${rest}" 0 ${at} before)
    string(LENGTH "${directive}" length)
    math(EXPR after "${at} + ${length}")
    string(SUBSTRING "${rest}" ${after} -1 rest)
    if(EXISTS ${dir}/${name})
      set(found ${dir}/${name})
    elseif(EXISTS ${INCLUDE_DIR}/${name})
      set(found ${INCLUDE_DIR}/${name})
    else()
      message(FATAL_ERROR "expand_glsl: ${file}: cannot find include \"${name}\"")
    endif()
    math(EXPR next "${depth} + 1")
    expand(${found} ${next} sub)
    string(APPEND text "${before}\n${sub}")
  endwhile()
  string(APPEND text "${rest}")
  string(SUBSTRING "${text}" 1 -1 text)  # the newline put in front
  set(${out_var} "${text}" PARENT_SCOPE)
endfunction()

expand(${INPUT} 0 source)
# Only ASCII reaches the GLSL ES compiler (its character set has no others, even in comments).
string(REGEX REPLACE "[^\t\r\n -~]+" "?" source "${source}")
file(WRITE ${OUTPUT_GLSL} "${source}")
file(WRITE ${OUTPUT_HEADER}
  "// Generated from ${INPUT} by src/backend/gles/expand_glsl.cmake: do not edit.\n"
  "#pragma once\n"
  "inline constexpr char ${VARIABLE}[] = R\"mobirt_glsl(${source})mobirt_glsl\";\n")
