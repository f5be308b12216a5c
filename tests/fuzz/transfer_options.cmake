veneer_fuzz(transfer_options SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/transfer_options.cpp LIBS veneer_pipeline)
