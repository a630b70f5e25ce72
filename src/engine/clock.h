// Stage timing for the engines' statistics (wall milliseconds).
#pragma once
#include <chrono>

namespace tessera {

using EngineClock = std::chrono::steady_clock;
inline double msSince(EngineClock::time_point t0) {
    return std::chrono::duration<double, std::milli>(EngineClock::now() - t0).count();
}

}  // namespace tessera
