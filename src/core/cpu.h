// What the CPU running the program can do, for the code paths compiled for wider vector units (a target
// attribute) and chosen at run time.
#pragma once

namespace tessera {

#if defined(__GNUC__) && defined(__x86_64__)
inline bool cpuHasAvx2() {
    static const bool has = [] {
        __builtin_cpu_init();
        return bool(__builtin_cpu_supports("avx2")) && bool(__builtin_cpu_supports("popcnt"));
    }();
    return has;
}
#else
inline bool cpuHasAvx2() {
    return false;
}
#endif

}  // namespace tessera
