// strata — the level schedule of the assembly tree (see symbolic.hpp).
//
// Source: Jung & Bae, "An improved direct linear equation solver using multi-GPU in
// multi-body dynamics", Adv. Eng. Softw. 2018 — the breadth-first reverse-level
// traversal of the elimination (assembly) tree. The depth of a front is its distance
// from its root; fronts of equal depth never include one another's ancestors, so each
// depth is a set of independent fronts. Levels are numbered so that the deepest depth is
// level 0 (processed first): level = max_depth − depth, and every child is one level
// below its parent. Fronts within a level are listed in increasing front number. One
// pass from the roots down (parents have larger numbers than their children) and a
// counting sort: O(number of fronts).
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {

LevelSchedule level_schedule(const AssemblyTree& t) {
  const index_t nf = t.n_fronts();
  LevelSchedule s;
  std::vector<index_t> depth(nf, 0);
  index_t max_depth = -1;
  for (index_t f = nf - 1; f >= 0; --f) {
    depth[f] = t.parent[f] == -1 ? 0 : depth[t.parent[f]] + 1;
    if (depth[f] > max_depth) max_depth = depth[f];
  }
  const index_t n_levels = max_depth + 1;  // 0 when there are no fronts
  s.level_of.resize(nf);
  s.level_offsets.assign(n_levels + 1, 0);
  for (index_t f = 0; f < nf; ++f) {
    s.level_of[f] = max_depth - depth[f];
    ++s.level_offsets[s.level_of[f] + 1];
  }
  for (index_t l = 0; l < n_levels; ++l) s.level_offsets[l + 1] += s.level_offsets[l];
  s.fronts.resize(nf);
  std::vector<index_t> next(s.level_offsets.begin(), s.level_offsets.end() - 1);
  for (index_t f = 0; f < nf; ++f) s.fronts[next[s.level_of[f]]++] = f;
  return s;
}

}  // namespace strata::symbolic
