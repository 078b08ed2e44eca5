// tools/report.h — what `hashcc train` prints at the end: image fit on the training views and,
// when the scene has reference cameras, pose error (formulas.md §7) and the focal against the reference.
#pragma once
#include "train/trainer.h"

namespace hashcc {
void print_train_report(Trainer& tr);
}  // namespace hashcc
