veneer_fuzz(pfm SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/pfm.cpp LIBS veneer_io)
