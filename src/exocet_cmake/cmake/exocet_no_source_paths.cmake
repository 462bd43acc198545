# No absolute source path in a binary: __FILE__ (in gtest's and rosconsole's messages, assert) names a file relative
# to the workspace, as when ccache's base_dir (set by the Makefile) rewrites the paths it compiles. Applies to the
# packages that find_package(catkin COMPONENTS exocet_cmake).
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" OR CMAKE_CXX_COMPILER_ID MATCHES "Clang")
  get_filename_component(_exocet_workspace "${CMAKE_SOURCE_DIR}/.." ABSOLUTE)
  add_compile_options("-fmacro-prefix-map=${_exocet_workspace}/=")
endif()
