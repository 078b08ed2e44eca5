#include <catch2/catch.hpp>
#include "core/parallel.h"
TEST_CASE("rng streams are reproducible and independent", "[core]") {
  hashcc::Rng a(42, 1), b(42, 1), c(42, 2);
  REQUIRE(a.next_u32() == b.next_u32());
  REQUIRE(a.next_u32() != c.next_u32());
}
