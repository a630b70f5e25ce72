// FNV-1a, 64 bits (Fowler, Noll, Vo): the content keys of tile scene hashes, deformation-key topology and
// the shadow-map cache. Not for security; equal input bytes give equal keys on every machine of one kind.
#pragma once
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace tessera {

struct Fnv1a64 {
    uint64_t h = 1469598103934665603ull;
    void bytes(const void* data, size_t n) {
        const auto* p = static_cast<const unsigned char*>(data);
        for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
    }
    // The object representation of a value: only for types without padding bytes.
    template <typename T>
    void value(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        bytes(&v, sizeof v);
    }
};

}  // namespace tessera
