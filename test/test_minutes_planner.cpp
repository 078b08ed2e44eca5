// test/test_minutes_planner.cpp — `--minutes`' planner (train/minutes_planner.h) on a clock the
// test sets: the plan after the 4th step, the one refinement at 10% of the budget, the
// extension when the plan runs out early, and a resumed run's refinement clock.
#include <catch2/catch.hpp>

#include "train/minutes_planner.h"

using namespace hashcc;

namespace {

// A session in which step k (1-based) ends at `ends[k-1]` seconds: runs the planner's
// after_step for each, as Trainer::run does (st.step and st.elapsed updated first).
struct FakeSession {
  double now = 0;
  TrainState st;
  MinutesPlanner planner;
  int64_t session_steps = 0;
  explicit FakeSession(double budget) : planner(budget, [this] { return now; }) {}
  bool step(double end) {
    now = end;
    ++st.step;
    ++session_steps;
    st.elapsed = end;
    return planner.after_step(st, session_steps);
  }
};

}  // namespace

TEST_CASE("minutes planner: plans after the 4th step from steps 2-4, refines once at 10%",
          "[trainer][minutes]") {
  FakeSession s(100.0);  // a 100-second budget
  CHECK_FALSE(s.step(5.0));  // step 1 warms up: slow, and not counted
  CHECK_FALSE(s.step(6.0));
  CHECK_FALSE(s.step(7.0));
  REQUIRE(s.step(8.0));  // steps 2-4: 1 s each; 92 s left at step 4
  CHECK(s.st.planned_steps == 4 + 92);
  CHECK_FALSE(s.st.plan_refined);
  // Then the steps take 0.5 s: at 10% of the budget (and > 4 steps after the plan) the plan is
  // refined once from the steps since the plan.
  double t = 8.0;
  bool refined = false;
  while (!refined) {
    t += 0.5;
    refined = s.step(t);
  }
  CHECK(s.st.elapsed >= 10.0);
  CHECK(s.st.plan_refined);
  CHECK(s.st.planned_steps == s.st.step + int64_t((100.0 - t) / 0.5));
  // Never again.
  for (int i = 0; i < 50; ++i) CHECK_FALSE(s.step(t += 0.5));
}

TEST_CASE("minutes planner: a plan that runs out while a step still fits is extended",
          "[trainer][minutes]") {
  FakeSession s(20.0);
  s.step(1.0);
  s.step(3.0);
  s.step(5.0);
  s.step(7.0);  // 2 s a step: 13 s left = 6 more steps
  REQUIRE(s.st.planned_steps == 4 + 6);
  double t = 7.0;
  while (s.st.step < s.st.planned_steps) s.step(t += 1.0);  // they ran at 1 s (refined at 10%)
  // At the end of the plan: time left for more steps at the session's pace: extended.
  const int64_t before = s.st.planned_steps;
  if (20.0 - t >= 1.0) {
    REQUIRE(s.planner.extend(s.st, s.session_steps));
    CHECK(s.st.planned_steps > before);
  }
  // With no time left for a step, the run ends.
  s.st.elapsed = 19.9;
  s.now = 19.9;
  CHECK_FALSE(s.planner.extend(s.st, s.session_steps));
}

TEST_CASE("minutes planner: a resumed run not refined yet refines from this session's clock",
          "[trainer][minutes]") {
  // Resumed: planned in the first session (200 steps), which ended at step 50 after 6 s.
  TrainState st;
  st.step = 50;
  st.elapsed = 6.0;
  st.planned_steps = 200;
  double now = 0;  // this session's clock; its steps take 2 s
  MinutesPlanner p(100.0, [&] { return now; });
  int64_t n = 0;
  bool changed = false;
  while (!changed && now < 40) {
    now += 2.0;
    ++st.step;
    st.elapsed = 6.0 + now;
    changed = p.after_step(st, ++n);
  }
  REQUIRE(changed);
  CHECK(st.plan_refined);
  CHECK(st.elapsed >= 10.0);
  CHECK(n > 1 + 4);  // more than 4 steps after this session's first
  // Refined from the steps after this session's first, at 2 s each.
  CHECK(st.planned_steps == st.step + int64_t((100.0 - st.elapsed) / 2.0));
}
