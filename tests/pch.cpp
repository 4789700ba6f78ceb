// The translation unit that makes the test files' precompiled header (tests/CMakeLists.txt).
