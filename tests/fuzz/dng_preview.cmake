veneer_fuzz(dng_preview SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/dng_preview.cpp LIBS veneer_io)
