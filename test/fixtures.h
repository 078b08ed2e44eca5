// test/fixtures.h — shared set-ups for tests that train: a tiny, fast TrainConfig.
#pragma once
#include <string>

#include "model/trainer.h"

namespace hashcc::test {

// Width 16, colour width 8, an 8×8 ray grid, 16 samples, no progress bar, no periodic
// checkpoint or preview (final ones only): a step takes milliseconds.
inline TrainConfig tiny_train_config(const std::string& data, const std::string& out,
                                     int64_t steps) {
  TrainConfig c;
  c.data = data;
  c.out = out;
  c.model.width = 16;
  c.model.rgb_width = 8;
  c.rays = 64;
  c.samples = 16;
  c.steps = steps;
  c.progress = false;
  c.checkpoint_minutes = 1e9;
  c.preview_minutes = 1e9;
  return c;
}

}  // namespace hashcc::test
