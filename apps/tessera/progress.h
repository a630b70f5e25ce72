// Progress reporting of the CLI, kept apart from the clock and the terminal so that tests can feed it
// (time, work done) pairs: the time-left estimate and the one-line-per-percent reporter of `--progress`.
#pragma once
#include <algorithm>
#include <cstdint>
#include <optional>

namespace tessera::cli {

// Time left from the fraction of the work done (the engines report work done and the total through
// RenderSettings::progress). Two things make the naive elapsed * (1 - f) / f estimate drift:
//  - set-up before the first report (splitting, BVH build) counts as if it were work, so early estimates
//    are too long: the rate here is measured from the first report on;
//  - work is not uniform in cost, so the rate wanders: the estimated finish time is smoothed with a time
//    constant of a quarter of the time since the first report (at most `smoothingSeconds`), which keeps
//    the shown value from jumping at every report at any render length.
class TimeLeftEstimate {
  public:
    explicit TimeLeftEstimate(double smoothingSeconds = 2.0) : tau_(smoothingSeconds) {}

    // `seconds` since the render started; `done` of `total` units finished. Reports may come in any order
    // from several threads (the caller serialises them); a report with less work done than one already
    // seen is ignored.
    void update(double seconds, int64_t done, int64_t total) {
        if (total <= 0 || done < lastDone_) return;
        total_ = total;
        lastDone_ = done;
        if (firstTime_ < 0) {
            firstTime_ = seconds;
            firstDone_ = done;
            lastTime_ = seconds;
            return;
        }
        const double dt = seconds - firstTime_;
        const int64_t work = done - firstDone_;
        if (dt <= 0 || work <= 0) return;
        const double rate = double(work) / dt;  // units per second since the first report
        const double finish = seconds + double(total - done) / rate;
        if (!hasFinish_) {
            finish_ = finish;
            hasFinish_ = true;
        } else {
            const double tau = std::min(tau_, 0.25 * dt);
            const double alpha = tau > 0 ? std::min(1.0, std::max(0.0, seconds - lastTime_) / tau) : 1.0;
            finish_ += alpha * (finish - finish_);
        }
        lastTime_ = std::max(lastTime_, seconds);
        if (done >= total) finish_ = seconds;
    }

    // Seconds left at time `seconds`, once two reports with work between them have been seen.
    std::optional<double> secondsLeft(double seconds) const {
        if (!hasFinish_) return std::nullopt;
        return std::max(0.0, finish_ - seconds);
    }

    double fraction() const { return total_ > 0 ? double(std::max<int64_t>(lastDone_, 0)) / total_ : 0.0; }

  private:
    double tau_;
    double firstTime_ = -1, lastTime_ = 0, finish_ = 0;
    int64_t firstDone_ = 0, lastDone_ = -1, total_ = 0;
    bool hasFinish_ = false;
};

// Whole percentages for `--progress`: step() returns the new percentage when (done, total) reaches a whole
// percent above the last one returned, else nothing. So each percentage is reported at most once, in
// increasing order, and 100 only when all the work is done.
class PercentSteps {
  public:
    std::optional<int> step(int64_t done, int64_t total) {
        if (total <= 0) return std::nullopt;
        done = std::clamp<int64_t>(done, 0, total);
        // done * 100 cannot overflow: sample counts stay far below 2^56.
        const int percent = int(done * 100 / total);
        if (percent <= last_) return std::nullopt;
        last_ = percent;
        return percent;
    }
    // Percentages already reported start above this (e.g. 0 after printing "progress 0%" up front).
    void markReported(int percent) { last_ = std::max(last_, percent); }
    int last() const { return last_; }

  private:
    int last_ = -1;
};

}  // namespace tessera::cli
