# cutsim_add_module(NAME SOURCES ... [PUBLIC_DEPS ...] [PRIVATE_DEPS ...])
# One library target per module: cutsim_<name>, aliased cutsim::<name>, with
# public headers under src/<name>/include/cutsim/<name>/.
function(cutsim_add_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(cutsim_${name} STATIC ${ARG_SOURCES})
  add_library(cutsim::${name} ALIAS cutsim_${name})
  target_include_directories(cutsim_${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_link_libraries(cutsim_${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  set_target_properties(cutsim_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON)
endfunction()
