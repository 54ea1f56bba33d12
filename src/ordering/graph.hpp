// strata — undirected adjacency graphs of sparse matrix patterns.
#pragma once

#include <vector>

#include "base/default_init.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::ordering {

/// Adjacency structure of an undirected graph in CSR form (0-based): the neighbours of
/// vertex v are adjncy[xadj[v] .. xadj[v+1]-1], sorted, without self loops, and every
/// edge appears in both directions. adjncy's resize leaves the new entries uninitialized:
/// the builders write every entry they keep, and the analysis's graph of B + Bᵀ
/// (analysis/patterns.hpp) sizes it for both halves of each column before it knows their
/// union, so that the room it does not use is never touched.
struct Graph {
  index_t n = 0;
  std::vector<index_t> xadj{0};
  UninitVector<index_t> adjncy;
  index_t n_edges_directed() const { return xadj.back(); }
};

/// The graph of the pattern of A + Aᵀ without the diagonal, for a square matrix of any
/// layout and storage. Throws InvalidInput if A is not square.
Graph graph_of(const SparseMatrix& a);

/// The subgraph induced by `vertices` (original numbers); local vertex i is
/// vertices[i]. Edges to vertices outside the set are dropped.
Graph induced_subgraph(const Graph& g, const std::vector<index_t>& vertices);

}  // namespace strata::ordering
