// --focal-fov: the starting focal from a field-of-view prior (issue 49), square pixels.
#include <catch2/catch.hpp>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "train/trainer.h"
#include "test/fixtures.h"

using namespace hashcc;

TEST_CASE("focal prior: --focal-fov starts at fx = fy = W / (2 tan(fov/2)); 0 is the paper's W, H",
          "[trainer][focal]") {
  const std::string data = test::sim_scene("focal_prior", 6, 40, 30);
  TrainConfig c = test::tiny_train_config(data, "", 10);
  {
    const Trainer t(c);  // the paper's start: fx = W, fy = H (anisotropic for 4:3 images)
    CHECK(focal_fx(t.focal(), t.image_size()) == Approx(40).epsilon(1e-6));
    CHECK(focal_fy(t.focal(), t.image_size()) == Approx(30).epsilon(1e-6));
  }
  c.focal_fov = 90;  // tan(45°) = 1: the focal is half the width, on both axes
  {
    const Trainer t(c);
    CHECK(focal_fx(t.focal(), t.image_size()) == Approx(20).epsilon(1e-6));
    CHECK(focal_fy(t.focal(), t.image_size()) == Approx(20).epsilon(1e-6));
  }
  c.focal_fov = 65;
  CHECK(focal_for_fov(504, 65) == Approx(395.56).margin(0.005));
  c.focal_fx = c.focal_fy = 33;  // --focal is a known focal: it wins over the prior
  {
    const Trainer t(c);
    CHECK(focal_fx(t.focal(), t.image_size()) == Approx(33).epsilon(1e-6));
    CHECK(focal_fy(t.focal(), t.image_size()) == Approx(33).epsilon(1e-6));
  }
}

TEST_CASE("focal prior: range checked by name; config.json round trip; absent key = 0",
          "[trainer][focal][hard]") {
  TrainConfig c;
  c.data = "x";
  c.focal_fov = 5;
  CHECK_THROWS_WITH(validate_train_config(c), Catch::Contains("--focal-fov"));
  c.focal_fov = 180;
  CHECK_THROWS_WITH(validate_train_config(c), Catch::Contains("--focal-fov"));
  c.focal_fov = 65;
  const TrainConfig back = train_config_from_json(train_config_json(c), "config.json");
  CHECK(back.focal_fov == 65);
  // An older config.json (before the key existed) starts as it always did.
  nlohmann::json j = nlohmann::json::parse(train_config_json(c));
  j.erase("focal_fov");
  CHECK(train_config_from_json(j.dump(), "config.json").focal_fov == 0);
}

TEST_CASE("focal prior: a plan's later stage keeps the focal of the cameras it starts from",
          "[trainer][focal]") {
  // A plan sets focal_fov in its base, so every stage's config carries it; a stage that starts
  // from the stage before (--cameras-from) must keep that stage's learned focal, not restart it
  // from the prior.
  const std::string data = test::sim_scene("focal_prior_from", 6, 40, 30);
  const std::string first = test::fresh_dir("focal_prior_stage1");
  TrainConfig c = test::tiny_train_config(data, first, 10);
  c.fx_only = true;
  c.focal_fx = c.focal_fy = 27;  // a focal the prior below would not give
  {
    Trainer t(c);
    t.save_checkpoint_now();
  }
  TrainConfig next = test::tiny_train_config(data, test::fresh_dir("focal_prior_stage2"), 10);
  next.fx_only = true;
  next.focal_fov = 90;  // the prior alone would give 20 px
  next.cameras_from = first;
  const Trainer t(next);
  CHECK(focal_fx(t.focal(), t.image_size()) == Approx(27).epsilon(1e-6));
  CHECK(focal_fy(t.focal(), t.image_size()) == Approx(27).epsilon(1e-6));
  // ... and its start-up report does not claim a focal from the prior it did not use.
  for (const std::string& line : t.init_report()) CHECK(line.find("field of view") == std::string::npos);
}
