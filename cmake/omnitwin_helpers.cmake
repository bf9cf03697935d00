# Small helpers shared by the folders' CMakeLists.

# omnitwin_sources(VAR DIR): the .cpp files of one source folder (not its tools/).
function(omnitwin_sources var dir)
  file(GLOB _srcs CONFIGURE_DEPENDS "${dir}/*.cpp")
  list(FILTER _srcs EXCLUDE REGEX ".*/([a-z_]+_)?main\\.cpp$")  # programs, not library code
  set(${var} ${_srcs} PARENT_SCOPE)
endfunction()

# omnitwin_library(NAME SRC...): a static library of the given sources, or an interface
# library while a folder holds only headers. Sets OMNITWIN_LINK_KIND (PUBLIC or INTERFACE) in
# the caller, for its target_link_libraries and target_include_directories calls.
macro(omnitwin_library name)
  if("${ARGN}" STREQUAL "")
    add_library(${name} INTERFACE)
    set(OMNITWIN_LINK_KIND INTERFACE)
  else()
    add_library(${name} STATIC ${ARGN})
    set(OMNITWIN_LINK_KIND PUBLIC)
  endif()
endmacro()
