// train/recipes.h — the built-in training plans: recipes/*.json, embedded as text at build time.
//
// CMakeLists.txt generates embedded_recipes() from the files (build/generated/
// recipes_embedded.cpp), so the binary needs no data folder and a recipe is added by adding a
// file. Kept apart from train/plan.h so the config reader (train_config.cpp, which checks a
// config's "preset" against these names) links without the plan runner (tools/fuzz.sh).
#pragma once
#include <string>
#include <utility>
#include <vector>

namespace hashcc {

// recipes/*.json as (name, text), sorted by name.
const std::vector<std::pair<std::string, std::string>>& embedded_recipes();
// Their names, in the same order.
const std::vector<std::string>& recipe_names();

}  // namespace hashcc
