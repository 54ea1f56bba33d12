// strata — adjacency graphs of sparse matrix patterns (see graph.hpp).
//
// What: the undirected graph of the pattern of A + Aᵀ without the diagonal, the input of
// every fill-reducing ordering, and induced subgraphs of it.
//
// Why: the orderings (nested dissection, METIS, AMD) see only the symmetric structure.
// The graph of A + Aᵀ does not depend on the layout (the CSR arrays of A are the CSC
// arrays of Aᵀ, and A + Aᵀ is symmetric) nor on the storage (a `lower` or `upper` matrix
// stands for the symmetric matrix whose graph is the same as that of its stored
// triangle plus its transpose). So every stored off-diagonal entry (i, j) becomes the two
// directed edges i→j and j→i, whatever the matrix's layout and storage.
//
// How: linear time and no comparison sort. The directed edges are bucketed by their
// target, then the buckets are swept in increasing target order, appending each target
// to the row of its source: every row then comes out sorted, and duplicates (an entry
// stored in both triangles, or repeated) are adjacent and dropped in a compaction pass.
// This is the two-pass bucket transpose of Gustavson (1978).
#include "ordering/graph.hpp"

#include <algorithm>
#include <string>

#include "strata/errors.hpp"

namespace strata::ordering {

Graph graph_of(const SparseMatrix& a) {
  if (a.n_rows != a.n_cols)
    throw InvalidInput("graph_of: the matrix is not square (" + std::to_string(a.n_rows) + "x" +
                       std::to_string(a.n_cols) + ")");
  const index_t n = a.n_rows;
  if (n < 0) throw InvalidInput("graph_of: negative order " + std::to_string(n));
  if (static_cast<index_t>(a.offsets.size()) != n + 1)
    throw InvalidInput("graph_of: offsets has " + std::to_string(a.offsets.size()) +
                       " entries, expected " + std::to_string(n + 1));
  if (a.offsets[0] != 0) throw InvalidInput("graph_of: offsets[0] is not 0");
  for (index_t j = 0; j < n; ++j)
    if (a.offsets[j + 1] < a.offsets[j])
      throw InvalidInput("graph_of: offsets[" + std::to_string(j + 1) + "] decreases");
  if (static_cast<index_t>(a.indices.size()) < a.offsets[n])
    throw InvalidInput("graph_of: indices is shorter than offsets[n]");

  // Pass 1: bucket every directed edge (u → v) of the symmetrized pattern by v, storing u.
  std::vector<index_t> start(n + 1, 0);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      if (i < 0 || i >= n)
        throw InvalidInput("graph_of: indices[" + std::to_string(p) + "] = " + std::to_string(i) +
                           " is out of range [0, " + std::to_string(n) + ")");
      if (i == j) continue;
      ++start[i + 1];
      ++start[j + 1];
    }
  for (index_t v = 0; v < n; ++v) start[v + 1] += start[v];
  std::vector<index_t> source(start[n]);
  {
    std::vector<index_t> next(start.begin(), start.end() - 1);
    for (index_t j = 0; j < n; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
        const index_t i = a.indices[p];
        if (i == j) continue;
        source[next[i]++] = j;  // edge j → i, bucket i
        source[next[j]++] = i;  // edge i → j, bucket j
      }
  }
  // The symmetrized edge set has as many edges leaving each vertex as entering it, so the
  // bucket sizes are also the row sizes (with duplicates).
  // Pass 2: sweep targets in increasing order and append each to its source's row.
  Graph g;
  g.n = n;
  UninitVector<index_t> rows(start[n]);  // every slot written by pass 2
  {
    std::vector<index_t> next(start.begin(), start.end() - 1);
    for (index_t v = 0; v < n; ++v)
      for (index_t p = start[v]; p < start[v + 1]; ++p) rows[next[source[p]]++] = v;
  }
  source.clear();
  source.shrink_to_fit();
  // Pass 3: drop adjacent duplicates, compacting in place.
  g.xadj.assign(n + 1, 0);
  index_t out = 0;
  for (index_t u = 0; u < n; ++u) {
    index_t last = -1;
    for (index_t p = start[u]; p < start[u + 1]; ++p) {
      if (rows[p] == last) continue;
      last = rows[p];
      rows[out++] = last;
    }
    g.xadj[u + 1] = out;
  }
  rows.resize(out);
  rows.shrink_to_fit();
  g.adjncy = std::move(rows);
  return g;
}

Graph induced_subgraph(const Graph& g, const std::vector<index_t>& vertices) {
  const index_t m = static_cast<index_t>(vertices.size());
  std::vector<index_t> local(g.n, -1);
  for (index_t i = 0; i < m; ++i) {
    const index_t v = vertices[i];
    if (v < 0 || v >= g.n)
      throw InvalidInput("induced_subgraph: vertices[" + std::to_string(i) + "] = " +
                         std::to_string(v) + " is out of range [0, " + std::to_string(g.n) + ")");
    if (local[v] >= 0)
      throw InvalidInput("induced_subgraph: vertex " + std::to_string(v) + " is repeated at " +
                         std::to_string(i));
    local[v] = i;
  }
  Graph s;
  s.n = m;
  s.xadj.assign(m + 1, 0);
  for (index_t i = 0; i < m; ++i) {
    const index_t v = vertices[i];
    for (index_t p = g.xadj[v]; p < g.xadj[v + 1]; ++p)
      if (local[g.adjncy[p]] >= 0) s.adjncy.push_back(local[g.adjncy[p]]);
    // Keep rows sorted in the local numbering (local order need not follow global order).
    std::sort(s.adjncy.begin() + s.xadj[i], s.adjncy.end());
    s.xadj[i + 1] = static_cast<index_t>(s.adjncy.size());
  }
  return s;
}

}  // namespace strata::ordering
