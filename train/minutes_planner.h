// train/minutes_planner.h — `--minutes`: how many steps fit the time budget.
//
// The learning-rate schedules decay over a planned number of steps (formulas.md §6), but a
// budget in minutes gives time, not steps. The planner turns one into the other as the run goes:
//   1. plan: after the session's 4th step, from the time of steps 2–4 (step 1 warms caches and
//      allocates), the steps that fit the rest of the budget;
//   2. refine, once, at 10% of the budget, from the steps since the plan: three early steps are
//      a noisy clock (measured: steps 2–4 ran ~20% slower than the run's average, so a run
//      planned on them stopped at 85% of its budget). The schedules stretch to the new total;
//      at 10% of the run that moves the lr by a few percent, once;
//   3. extend: a plan that runs out while one more step still fits the budget is re-planned
//      instead of ending early (its steps ran slower than the rest, or a resumed run was given
//      more minutes).
// A resumed run whose plan was not refined yet starts its refinement clock after this session's
// first step (a new process: the first session's clock is gone).
#pragma once
#include <cstdint>
#include <functional>

#include "train/trainer.h"

namespace hashcc {

class MinutesPlanner {
 public:
  // budget_s: the run's budget in seconds; now(): this session's seconds so far (each call
  // reads the clock anew).
  MinutesPlanner(double budget_s, std::function<double()> now)
      : budget_(budget_s), now_(std::move(now)) {}
  // After a step: session_steps = step_once() calls in this session (the first = 1), st.elapsed
  // already updated. Counted in calls, not st.step: a divergence-guard restore moves st.step
  // back, but the time per call is what the plan needs. True when st.planned_steps changed.
  bool after_step(TrainState& st, int64_t session_steps);
  // The plan ran out (st.step reached it): true when one more step fits the budget and the
  // plan was extended, false when the run ends.
  bool extend(TrainState& st, int64_t session_steps) const;

 private:
  // Seconds a step, measured in this session: since the plan, else since the session's first
  // step; with no such steps yet, the run's average.
  double seconds_per_step(const TrainState& st, int64_t session_steps) const;
  // The steps that fit the rest of the budget at per_step seconds each (at least one).
  void plan(TrainState& st, double per_step) const;

  double budget_;
  std::function<double()> now_;
  double t_after_first_ = 0;  // session seconds after its first step
  int64_t plan_step_ = -1;    // the session step count and time of the plan (−1: none yet)
  double plan_time_ = 0;
};

}  // namespace hashcc
