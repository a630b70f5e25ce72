// An allocator for large buffers touched once (the frame's image, the weld's scratch arrays): a request of
// at least kHugeBufferBytes (1 MB) is aligned to 2 MB, rounded up to whole 2 MB pages and offered to the
// kernel's transparent huge pages (madvise), so that touching it takes one page fault per 2 MB instead of
// one per 4 KB. On a virtual machine each fault is expensive (about 10 us here): a 1024 x 1024 RGBA float
// image is 4,096 faults, about 10% of the whole teapot frame (issue 18). Smaller requests, and systems
// without madvise, get plain operator new.
#pragma once
#include <cstddef>
#include <cstdlib>
#include <new>
#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace tessera {

inline constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;
inline constexpr std::size_t kHugeBufferBytes = std::size_t(1) << 20;

template <class T>
struct BufferAllocator {
    using value_type = T;
    BufferAllocator() noexcept = default;
    template <class U>
    BufferAllocator(const BufferAllocator<U>&) noexcept {}

    T* allocate(std::size_t n) {
        const std::size_t bytes = n * sizeof(T);
#if defined(__linux__)
        if (bytes >= kHugeBufferBytes) {
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
        if (n * sizeof(T) >= kHugeBufferBytes) {
            std::free(p);
            return;
        }
#endif
        ::operator delete(p);
        (void)n;
    }
    template <class U>
    bool operator==(const BufferAllocator<U>&) const noexcept {
        return true;
    }
};

}  // namespace tessera
