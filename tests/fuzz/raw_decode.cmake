veneer_fuzz(raw_decode SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/raw_decode.cpp LIBS veneer_io)
