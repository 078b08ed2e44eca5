#include "tools/report.h"

#include <cmath>
#include <fmt/core.h>

namespace hashcc {

void print_train_report(Trainer& tr) {
  (void)tr;  // filled in when the evaluation library lands
}

}  // namespace hashcc
