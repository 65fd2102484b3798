#pragma once
// The few records of a long list that matter most, kept in the list's
// order; the records sorted into kinds.
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

/// Records sorted into kinds, in the order the kinds first appear.
struct RecordGroups {
  struct Group {
    std::size_t first = 0;    ///< its first record (which stands for the kind)
    std::size_t records = 0;  ///< how many
    std::size_t worst = 0;    ///< the first of its worst records
    int first_line = 0, last_line = 0;
  };
  std::vector<Group> groups;
  std::vector<std::size_t> group_of;  ///< each record's group
};

/// Groups `count` records: `same_kind(i, j)` whether two are of one kind,
/// `worse(i, j)` whether record i is strictly worse than j, `line_of(i)`
/// its NC line. (A few kinds: each record is tried against each kind.)
template <class SameKind, class Worse, class LineOf>
RecordGroups group_records(std::size_t count, SameKind same_kind, Worse worse, LineOf line_of) {
  RecordGroups out;
  out.group_of.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    std::size_t g = 0;
    while (g < out.groups.size() && !same_kind(out.groups[g].first, i)) ++g;
    if (g == out.groups.size()) out.groups.push_back({i, 0, i, line_of(i), line_of(i)});
    RecordGroups::Group& k = out.groups[g];
    ++k.records;
    if (worse(i, k.worst)) k.worst = i;
    k.first_line = std::min(k.first_line, line_of(i));
    k.last_line = std::max(k.last_line, line_of(i));
    out.group_of[i] = g;
  }
  return out;
}

}  // namespace cutsim
