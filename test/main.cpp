// The Catch2 runner for hashcc_tests. Tests are tagged by kernel/area ([fourier], [camera], …)
// and by kind ([grad] gradient checks, [hard] numerically hard cases, [float] float-vs-double,
// [e2e] end-to-end); run a subset with e.g. `hashcc_tests "[grad]"`.
#define CATCH_CONFIG_MAIN
#include <catch2/catch.hpp>
