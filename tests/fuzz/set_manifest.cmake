veneer_fuzz(set_manifest SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/set_manifest.cpp LIBS veneer_io)
