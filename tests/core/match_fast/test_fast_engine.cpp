// The fast engine's maps against the exact methods.
#include <gtest/gtest.h>

#include "veneer/match/fast.hpp"
