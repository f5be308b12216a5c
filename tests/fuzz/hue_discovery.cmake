veneer_fuzz(hue_discovery SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/hue_discovery.cpp LIBS veneerd_hw)
