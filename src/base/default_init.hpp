// strata — vectors whose resize does not zero the new elements.
//
// std::vector::resize value-initializes what it adds: for a buffer of doubles that is
// written entirely before it is read (a contribution block copied out of its front, say)
// that is a pass over the memory for nothing, once per front and factorization.
// DefaultInitAllocator default-initializes instead (nothing, for a trivial type);
// construction with arguments (resize(n, x), push_back, copies) is the standard
// allocator's.
#pragma once

#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace strata {

/// std::allocator<T> whose construct(p) default-initializes (leaves a trivial T
/// uninitialized) instead of value-initializing; every other construction is unchanged.
template <class T>
class DefaultInitAllocator : public std::allocator<T> {
 public:
  using value_type = T;
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  DefaultInitAllocator() noexcept = default;
  template <class U>
  DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}

  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

template <class T, class U>
bool operator==(const DefaultInitAllocator<T>&, const DefaultInitAllocator<U>&) noexcept {
  return true;
}

/// A std::vector whose resize leaves the new elements of a trivial type uninitialized.
template <class T>
using UninitVector = std::vector<T, DefaultInitAllocator<T>>;

}  // namespace strata
