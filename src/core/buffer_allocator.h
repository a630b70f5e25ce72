// An allocator for large buffers touched once (the frame's image, the weld's scratch arrays): a request of
// at least kHugeBufferBytes (1 MB) is aligned to 2 MB, rounded up to whole 2 MB pages and offered to the
// kernel's transparent huge pages (madvise), so that touching it takes one page fault per 2 MB instead of
// one per 4 KB. On a virtual machine each fault is expensive (about 10 us here): a 1024 x 1024 RGBA float
// image is 4,096 faults, about 10% of the whole teapot frame (issue 18). Smaller requests, and systems
// without madvise, get plain operator new. kHugePages = false: always plain operator new, for scratch
// that is reused from tile to tile (faulted in once per thread) and whose size follows the scene, where a
// rounding up to whole 2 MB pages is memory held for nothing.
#pragma once
#include <cstddef>
#include <cstdlib>
#include <new>
#include <type_traits>
#include <utility>
#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace tessera {

inline constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;
inline constexpr std::size_t kHugeBufferBytes = std::size_t(1) << 20;

template <class T, bool kHugePages = true>
struct BufferAllocator {
    using value_type = T;
    template <class U>
    struct rebind {
        using other = BufferAllocator<U, kHugePages>;
    };
    BufferAllocator() noexcept = default;
    template <class U>
    BufferAllocator(const BufferAllocator<U, kHugePages>&) noexcept {}

    T* allocate(std::size_t n) {
        const std::size_t bytes = n * sizeof(T);
#if defined(__linux__)
        if (kHugePages && bytes >= kHugeBufferBytes) {
            const std::size_t rounded = (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
            void* p = std::aligned_alloc(kHugePageBytes, rounded);
            if (!p) throw std::bad_alloc();
            madvise(p, rounded, MADV_HUGEPAGE);  // advice only: without huge pages it is plain memory
            return static_cast<T*>(p);
        }
#endif
        return static_cast<T*>(::operator new(bytes));
    }
    void deallocate(T* p, std::size_t n) noexcept {
#if defined(__linux__)
        if (kHugePages && n * sizeof(T) >= kHugeBufferBytes) {
            std::free(p);
            return;
        }
#endif
        ::operator delete(p);
        (void)n;
    }
    template <class U>
    bool operator==(const BufferAllocator<U, kHugePages>&) const noexcept {
        return true;
    }
};

// BufferAllocator that default-initializes (no zeroing on resize), for arrays that are then filled in
// parallel (the ray tracer's subpatch forest, the Reyes pieces): a serial fill of the whole array would
// only add time and memory traffic, and on huge pages their first touch is one fault per 2 MB (the
// forest's per-4 KB faults were a tenth of the 24 Big Guys rt frame).
template <class T, bool kHugePages = true>
struct DefaultInitAllocator : BufferAllocator<T, kHugePages> {
    template <class U>
    struct rebind {
        using other = DefaultInitAllocator<U, kHugePages>;
    };
    DefaultInitAllocator() = default;
    template <class U>
    DefaultInitAllocator(const DefaultInitAllocator<U, kHugePages>&) noexcept {}
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        // Plain aggregates (Bounds3, Piece: their default member initializers would fill the array
        // serially) are left for the code that fills them; other types are default-initialized.
        if constexpr (!(std::is_aggregate_v<U> && std::is_trivially_copyable_v<U>))
            ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

}  // namespace tessera
