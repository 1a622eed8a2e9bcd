# cmake -DSOURCE=... -DBUILD=... -DGENERATOR=... -DTETRIG_SOURCE_DIR=... -DCC=... -DCXX=... -P subproject_check.cmake
# Configures tests/install/subproject (a parent project that adds tetrig with add_subdirectory) in a
# fresh build folder, so that no cached option from an earlier run hides a changed default.
file(REMOVE_RECURSE ${BUILD})
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SOURCE} -B ${BUILD} -G ${GENERATOR} -DTETRIG_SOURCE_DIR=${TETRIG_SOURCE_DIR}
                        -DCMAKE_C_COMPILER=${CC} -DCMAKE_CXX_COMPILER=${CXX}
                RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${out}${err}")
if(NOT result EQUAL 0)
  message(FATAL_ERROR "configuring the parent project failed (${result})")
endif()
