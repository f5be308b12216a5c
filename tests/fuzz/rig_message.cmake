veneer_fuzz(rig_message SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/rig_message.cpp LIBS veneerd_lib veneer_proto)
