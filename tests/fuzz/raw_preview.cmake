veneer_fuzz(raw_preview SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/raw_preview.cpp LIBS veneerd_hw)
