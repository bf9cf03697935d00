# Small helpers shared by the folders' CMakeLists.

# omnitwin_sources(VAR DIR): the .cpp files of one source folder (not its tools/).
function(omnitwin_sources var dir)
  file(GLOB _srcs CONFIGURE_DEPENDS "${dir}/*.cpp")
  list(FILTER _srcs EXCLUDE REGEX ".*/main\\.cpp$")
  set(${var} ${_srcs} PARENT_SCOPE)
endfunction()
