// test/golden_folders.h — the committed input folders of `hashcc step` (test/data/golden_*/in,
// docs/golden-step.md "Committed inputs"), what each must exercise, and the command that wrote
// it. [golden][grad] (test_golden.cpp) and [golden][reference] (test_reference.cpp) run every
// one of them; "the committed golden inputs exercise what they should" checks the flags below
// against each folder's config.
#pragma once
#include <vector>

#include "model/model.h"

namespace hashcc::test {

struct GoldenFolder {
  const char* name;     // test/data/<name>/in
  Variant variant;
  Field field;
  bool c2f;             // a Fourier band / grid level partly on
  bool ndc = true;
  bool fx_only = false;
  bool p0 = false;      // P0.npy: a test-pose camera
  bool smooth = false;  // grid_smooth: the camera gradient is the smooth straight-through one,
                        // not the derivative of the forward (docs/math/grid_field.md)
  const char* command;  // the `hashcc step --make-inputs test/data/<name>/in` arguments
};

inline const std::vector<GoldenFolder>& golden_folders() {
  static const std::vector<GoldenFolder> f = {
      {"golden_nerfmm", Variant::nerfmm, Field::mlp, true, true, false, false, false,
       "--model nerfmm --c2f-alpha 4.3 --seed 2"},
      {"golden_sh", Variant::sh, Field::mlp, false, true, false, false, false, "--model sh --seed 3"},
      {"golden_hashcc", Variant::hashcc, Field::mlp, false, true, false, false, false,
       "--model hashcc --seed 1"},
      {"golden_grid", Variant::hashcc, Field::grid, true, true, false, false, false,
       "--model hashcc --field grid --c2f-alpha 2.5 --seed 4"},
      {"golden_nondc", Variant::hashcc, Field::mlp, false, false, false, false, false,
       "--model hashcc --no-ndc --seed 5"},
      {"golden_p0", Variant::sh, Field::grid, false, true, false, true, false,
       "--model sh --field grid --p0 --seed 6"},
      {"golden_fxonly", Variant::hashcc, Field::grid, true, true, true, false, false,
       "--model hashcc --field grid --fx-only --c2f-alpha 3.4 --seed 7"},
      {"golden_grid_smooth", Variant::hashcc, Field::grid, false, true, false, false, true,
       "--model hashcc --field grid --grid-smooth --seed 8"},
  };
  return f;
}

}  // namespace hashcc::test
