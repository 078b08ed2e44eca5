// train/minutes_planner.cpp — see minutes_planner.h.
#include "train/minutes_planner.h"

#include <algorithm>

namespace hashcc {

void MinutesPlanner::plan(TrainState& st, double per_step) const {
  st.planned_steps = st.step + std::max<int64_t>(1, int64_t((budget_ - st.elapsed) / per_step));
}

double MinutesPlanner::seconds_per_step(const TrainState& st, int64_t session_steps) const {
  if (plan_step_ >= 0 && session_steps > plan_step_)
    return (now_() - plan_time_) / double(session_steps - plan_step_);
  if (session_steps > 1) return (now_() - t_after_first_) / double(session_steps - 1);
  return st.step > 0 ? st.elapsed / double(st.step) : 0.0;
}

bool MinutesPlanner::after_step(TrainState& st, int64_t session_steps) {
  bool changed = false;
  if (session_steps == 1) t_after_first_ = now_();
  if (st.planned_steps > 0 && !st.plan_refined && plan_step_ < 0 && session_steps == 1) {
    plan_step_ = session_steps;  // resumed, not refined yet: the refinement clock starts here
    plan_time_ = t_after_first_;
  }
  if (st.planned_steps == 0 && session_steps == 4) {
    plan(st, (now_() - t_after_first_) / 3.0);
    plan_step_ = session_steps;
    plan_time_ = now_();
    changed = true;
  }
  if (!st.plan_refined && plan_step_ >= 0 && st.elapsed >= 0.1 * budget_ &&
      session_steps > plan_step_ + 4) {
    plan(st, seconds_per_step(st, session_steps));
    st.plan_refined = true;
    changed = true;
  }
  return changed;
}

bool MinutesPlanner::extend(TrainState& st, int64_t session_steps) const {
  const double per_step = st.planned_steps > 0 ? seconds_per_step(st, session_steps) : 0.0;
  if (!(per_step > 0 && budget_ - st.elapsed >= per_step)) return false;
  plan(st, per_step);
  return true;
}

}  // namespace hashcc
