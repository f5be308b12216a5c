veneer_fuzz(png SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/png.cpp LIBS veneer_io)
