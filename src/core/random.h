// Deterministic, stateless hashing for sample positions: the same pixel always gets the same jitter,
// whatever thread or bucket renders it (bit-identical images for any --threads).
#pragma once
#include <cstdint>

#include "core/hostdevice.h"

namespace tessera {

// 32-bit integer hash (Chris Wellons' "lowbias32" finaliser).
TESSERA_HD uint32_t hash32(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}
TESSERA_HD uint32_t hashCombine(uint32_t a, uint32_t b) { return hash32(a ^ (hash32(b) + 0x9e3779b9U + (a << 6) + (a >> 2))); }
// Uniform float in [0,1) from a hash (24 mantissa bits).
TESSERA_HD float hashToUnit(uint32_t h) { return float(h >> 8) * (1.f / 16777216.f); }

}  // namespace tessera
