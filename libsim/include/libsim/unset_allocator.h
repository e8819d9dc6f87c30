// An allocator whose containers leave new elements as they are: resize() writes nothing, where
// std::vector's own allocator zeroes them. For large buffers written whole before they are read
// (images, hit caches), so a new one costs no pass over its memory.
#pragma once

#include <memory>
#include <new>
#include <utility>

namespace trephine {

template <typename T>
struct UnsetAllocator : std::allocator<T> {
    template <typename U>
    struct rebind {
        using other = UnsetAllocator<U>;
    };
    UnsetAllocator() = default;
    template <typename U>
    UnsetAllocator(const UnsetAllocator<U>&) noexcept {}
    template <typename U>
    void construct(U* p) noexcept {
        ::new (static_cast<void*>(p)) U;
    }
    template <typename U, typename... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

} // namespace trephine
