veneer_fuzz(hue_http SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/hue_http.cpp LIBS veneerd_sim)
