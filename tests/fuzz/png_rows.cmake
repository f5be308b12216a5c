veneer_fuzz(png_rows SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/png_rows.cpp LIBS veneer_io z)
