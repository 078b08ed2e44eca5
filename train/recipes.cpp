// train/recipes.cpp — see recipes.h.
#include "train/recipes.h"

namespace hashcc {

const std::vector<std::string>& recipe_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const auto& [name, text] : embedded_recipes()) n.push_back(name);
    return n;
  }();
  return names;
}

}  // namespace hashcc
