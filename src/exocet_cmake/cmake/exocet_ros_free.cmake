# exocet_ros_free_target(<target> [HEADERS <header>...])
#
# Marks a target as ROS-free (a core library, a core gtest, a ROS-free tool or benchmark) and makes the build fail
# when it includes a ROS header, directly or through any header it includes:
# - a directory holding a poisoned copy (#error) of every header the installed ROS packages provide
#   (exocet_ros_headers.py, from the installed packages' file lists) goes first on the target's include path, so the
#   compiler resolving an include to a ROS header stops, naming the header and, in its "In file included from"
#   lines, the file that includes it;
# - HEADERS (the library's public headers) are preprocessed with the same include path and definitions, so that a
#   header no source of the library includes is checked as well (a stamp target the library depends on).
#
# Why not a grep of the sources for "#include <ros/": Debian installs ROS in /usr/include, on the compiler's
# default path, so leaving the catkin include directories out does not stop a core file from including ROS; and a
# grep sees neither an include that reaches ROS through another header (ours or a third party's), nor one that is
# spelled differently ("ros/time.h", <rosbag/bag.h>, <tf2/...>, <class_loader/...>, a generated message header), nor
# one in a branch the preprocessor does not take. Only the compiler knows which file an include resolves to.
#
# The target's own include directories stay as they are: give a ROS-free target its own include directory and its
# third-party ones (target_include_directories / target_link_libraries), never ${catkin_INCLUDE_DIRS}.
include_guard(GLOBAL)

set(_EXOCET_ROS_FREE_DIR "${CMAKE_CURRENT_LIST_DIR}")

# The poisoned headers, generated once per configure, again only when the installed packages may have changed.
function(_exocet_ros_poison_dir out_var)
  get_property(dir GLOBAL PROPERTY EXOCET_ROS_POISON_DIR)
  if(dir)
    set(${out_var} "${dir}" PARENT_SCOPE)
    return()
  endif()
  set(output "${CMAKE_BINARY_DIR}/exocet_ros_poison")
  # Where ROS packages are installed: the catkin workspaces this one overlays, /usr (Debian), /opt/ros/<distro>.
  string(REPLACE ":" ";" env_prefixes "$ENV{CMAKE_PREFIX_PATH}")
  file(GLOB opt_ros LIST_DIRECTORIES true /opt/ros/*)
  set(prefixes ${CATKIN_WORKSPACES} ${env_prefixes} ${CMAKE_PREFIX_PATH} /usr ${opt_ros})
  list(REMOVE_DUPLICATES prefixes)
  set(key "${prefixes}")
  foreach(stamp_file /var/lib/dpkg/status "${_EXOCET_ROS_FREE_DIR}/exocet_ros_headers.py")
    if(EXISTS "${stamp_file}")
      file(TIMESTAMP "${stamp_file}" t)
      string(APPEND key ";${t}")
    endif()
  endforeach()
  foreach(prefix ${prefixes})
    if(IS_DIRECTORY "${prefix}/share")
      file(TIMESTAMP "${prefix}/share" t)
      string(APPEND key ";${t}")
    endif()
  endforeach()
  set(old_key "")
  if(EXISTS "${output}/key.txt" AND EXISTS "${output}/ros_headers.txt")
    file(READ "${output}/key.txt" old_key)
  endif()
  if(NOT old_key STREQUAL key)
    if(PYTHON_EXECUTABLE)
      set(python "${PYTHON_EXECUTABLE}")
    else()
      find_package(Python3 REQUIRED COMPONENTS Interpreter)
      set(python "${Python3_EXECUTABLE}")
    endif()
    set(prefix_args)
    foreach(prefix ${prefixes})
      list(APPEND prefix_args --prefix "${prefix}")
    endforeach()
    set(exclude_args)
    if(CATKIN_DEVEL_PREFIX)  # this workspace's own generated headers are not on a ROS-free target's path at all
      set(exclude_args --exclude-prefix "${CATKIN_DEVEL_PREFIX}")
    endif()
    execute_process(
      COMMAND "${python}" "${_EXOCET_ROS_FREE_DIR}/exocet_ros_headers.py" --output "${output}" ${prefix_args}
              ${exclude_args}
      RESULT_VARIABLE status OUTPUT_VARIABLE summary ERROR_VARIABLE errors OUTPUT_STRIP_TRAILING_WHITESPACE)
    if(NOT status EQUAL 0)
      message(FATAL_ERROR "exocet_ros_free: listing the ROS headers failed (${status}): ${errors}")
    endif()
    file(WRITE "${output}/key.txt" "${key}")
    message(STATUS "exocet_ros_free: ${summary}")
  endif()
  set_property(GLOBAL PROPERTY EXOCET_ROS_POISON_DIR "${output}/poison")
  set(${out_var} "${output}/poison" PARENT_SCOPE)
endfunction()

function(exocet_ros_free_target target)
  cmake_parse_arguments(ARG "" "" "HEADERS" ${ARGN})
  if(ARG_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "exocet_ros_free_target(${target}): unexpected arguments ${ARG_UNPARSED_ARGUMENTS}")
  endif()
  _exocet_ros_poison_dir(poison)
  get_target_property(type ${target} TYPE)
  if(type STREQUAL "INTERFACE_LIBRARY")
    set(include_property INTERFACE_INCLUDE_DIRECTORIES)
    set(definition_property INTERFACE_COMPILE_DEFINITIONS)
  else()
    # BEFORE: ahead of every other directory, -isystem ones and the compiler's own (/usr/include) come later anyway.
    target_include_directories(${target} BEFORE PRIVATE "${poison}")
    set(include_property INCLUDE_DIRECTORIES)
    set(definition_property COMPILE_DEFINITIONS)
  endif()
  if(NOT ARG_HEADERS)
    return()
  endif()
  # One translation unit including every public header, preprocessed only (a fraction of a second) with the
  # target's include path (transitive: the directories of what it links) and definitions, the poison first.
  set(check_dir "${CMAKE_CURRENT_BINARY_DIR}/exocet_ros_free")
  set(unit "${check_dir}/${target}_headers.cpp")
  set(content "// Generated by exocet_ros_free_target(${target}): its public headers, each checked for ROS includes.\n")
  foreach(header ${ARG_HEADERS})
    get_filename_component(header "${header}" ABSOLUTE)
    string(APPEND content "#include \"${header}\"\n")
  endforeach()
  file(CONFIGURE OUTPUT "${unit}" CONTENT "${content}" @ONLY)
  set(stamp "${check_dir}/${target}_headers.stamp")
  set(includes "$<TARGET_PROPERTY:${target},${include_property}>")
  set(definitions "$<TARGET_PROPERTY:${target},${definition_property}>")
  set(standard)
  if(CMAKE_CXX_STANDARD)
    set(standard "${CMAKE_CXX${CMAKE_CXX_STANDARD}_STANDARD_COMPILE_OPTION}")
  endif()
  add_custom_command(
    OUTPUT "${stamp}"
    COMMAND "${CMAKE_CXX_COMPILER}" ${standard} -E "-I${poison}" "$<$<BOOL:${includes}>:-I$<JOIN:${includes},;-I>>"
            "$<$<BOOL:${definitions}>:-D$<JOIN:${definitions},;-D>>" -MD -MT "${stamp}" -MF "${stamp}.d"
            -o "${stamp}.i" "${unit}"
    COMMAND "${CMAKE_COMMAND}" -E remove "${stamp}.i"
    COMMAND "${CMAKE_COMMAND}" -E touch "${stamp}"
    DEPENDS "${unit}" ${ARG_HEADERS}
    DEPFILE "${stamp}.d"
    COMMENT "Checking that the public headers of ${target} include no ROS header"
    COMMAND_EXPAND_LISTS VERBATIM)
  add_custom_target(${target}_ros_free_headers ALL DEPENDS "${stamp}")
  if(NOT type STREQUAL "INTERFACE_LIBRARY")
    add_dependencies(${target} ${target}_ros_free_headers)
  endif()
endfunction()
