# exocet_long_running_allocator(target): links a node executable with jemalloc, which then serves every malloc of the
# process (its libraries' included: the executable's own dependency comes before libc in the lookup order).
# Why: a node that runs for hours with large short-lived buffers in several threads (tile rasters, SIFT pyramids,
# GeoTIFF blocks) fragments glibc's per-thread arenas, and its resident memory creeps up by tens of MB per 10 minutes
# of dive although what it holds does not grow (make soak); jemalloc's size classes and decay return those pages.
# exocet_common::heapUsage() and releaseFreeHeap() detect it at run time (mallctl) and use its statistics.
# A nodelet runs in its manager's process: give the manager jemalloc with LD_PRELOAD to get the same.
find_library(EXOCET_JEMALLOC_LIBRARY NAMES jemalloc libjemalloc.so.2)
if(NOT EXOCET_JEMALLOC_LIBRARY)
  message(FATAL_ERROR "jemalloc not found: apt-get install libjemalloc-dev (tools/debian-packages.txt)")
endif()

function(exocet_long_running_allocator target)
  # No --as-needed: nothing calls jemalloc by name, it is there to take malloc over.
  target_link_libraries(${target} "-Wl,--push-state,--no-as-needed" ${EXOCET_JEMALLOC_LIBRARY} "-Wl,--pop-state")
endfunction()
