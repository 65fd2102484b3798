#pragma once
// The few records of a long list that matter most, kept in the list's order.
#include <algorithm>
#include <cstddef>
#include <numeric>
#include <vector>

namespace cutsim {

/// The indices of the `n` of `count` records that come first by
/// `before(i, j)` (a strict order on indices), returned in index order;
/// all of them when there are no more than `n`.
template <class Before>
std::vector<std::size_t> first_n_in_order(std::size_t count, std::size_t n, Before before) {
  std::vector<std::size_t> idx(count);
  std::iota(idx.begin(), idx.end(), std::size_t{0});
  if (count > n) {
    std::nth_element(idx.begin(), idx.begin() + static_cast<std::ptrdiff_t>(n), idx.end(), before);
    idx.resize(n);
    std::sort(idx.begin(), idx.end());
  }
  return idx;
}

}  // namespace cutsim
