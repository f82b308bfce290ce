// The curvature terms of a beam grid's interpolation (docs/physics.md, "Interpolation on the grid").
// Bilinear interpolation of f between nodes a step h apart is high by u (1 - u) h^2 f_xx / 2 +
// v (1 - v) h^2 f_yy / 2 within a cell (u, v its fractions of a step): h^2 / 12 of the Laplacian on
// average, and an error with the grid's period that the lattice of a sky's pixels can sample
// coherently. Every backend subtracts
//   u (1 - u) [(1 - v) ex(i, j) + v ex(i, j + 1)] + v (1 - v) [(1 - u) ey(i, j) + u ey(i + 1, j)]
// with ex(i, j) = h^2 f_xx / 2 on the edge from node (i, j) to (i + 1, j) and ey(i, j) = h^2 f_yy / 2
// on the edge from (i, j) to (i, j + 1), each the mean of the second differences at the edge's two
// ends, halved. On an edge this is the one-dimensional rule, so the interpolation stays continuous
// from cell to cell; what is left is of order h^3.
//
// Layout: the n x n nodes (x fastest) of `width` numbers each are followed by n^2 records ex, in the
// transposed order (record n^2 + i n + j is ex(i, j)), then n^2 records ey in the nodes' order
// (record 2 n^2 + j n + i is ey(i, j)). A backend reads (ex(i, j), ex(i, j + 1)) and (ey(i, j),
// ey(i + 1, j)) as it reads a node and its neighbour along x (src/kernel/pixel.glsl, interpolate_weights).
#pragma once

#include <cstddef>
#include <vector>

namespace pisco::detail {

// h^2 f_xx (along_x) or h^2 f_yy at node (i, j) from its neighbours; 0 on the grid's edge.
inline double second_difference(const double* f, int n, std::size_t width, int i, int j, bool along_x,
                                std::size_t c) {
  const auto at = [&](int a, int b) { return f[(static_cast<std::size_t>(b) * n + a) * width + c]; };
  if (along_x) return i > 0 && i < n - 1 ? at(i + 1, j) - 2 * at(i, j) + at(i - 1, j) : 0.0;
  return j > 0 && j < n - 1 ? at(i, j + 1) - 2 * at(i, j) + at(i, j - 1) : 0.0;
}

// ex(i, j) (along_x) or ey(i, j) for number c of each node; 0 for an edge that leaves the grid.
inline double edge_curvature(const double* f, int n, std::size_t width, int i, int j, bool along_x, std::size_t c) {
  if (along_x ? i >= n - 1 : j >= n - 1) return 0.0;
  return (second_difference(f, n, width, i, j, along_x, c) +
          second_difference(f, n, width, along_x ? i + 1 : i, along_x ? j : j + 1, along_x, c)) /
         4.0;
}

// The interpolation at fractions (fu, fv) of cell (i, j) of number c, as every backend computes it.
inline double interpolate_grid(const double* f, int n, std::size_t width, int i, int j, double fu, double fv,
                               std::size_t c) {
  const auto at = [&](int a, int b) { return f[(static_cast<std::size_t>(b) * n + a) * width + c]; };
  const double gu = 1 - fu, gv = 1 - fv;
  const double ex0 = edge_curvature(f, n, width, i, j, true, c), ex1 = edge_curvature(f, n, width, i, j + 1, true, c);
  const double ey0 = edge_curvature(f, n, width, i, j, false, c), ey1 = edge_curvature(f, n, width, i + 1, j, false, c);
  return gu * gv * at(i, j) + fu * gv * at(i + 1, j) + gu * fv * at(i, j + 1) + fu * fv * at(i + 1, j + 1) -
         fu * gu * (gv * ex0 + fv * ex1) - fv * gv * (gu * ey0 + fu * ey1);
}

// Appends the edges' records to a grid of n x n nodes of `width` numbers each (the layout above).
inline void append_edge_curvature(std::vector<double>& grid, int n, std::size_t width) {
  const std::size_t nodes = static_cast<std::size_t>(n) * n;
  grid.resize(3 * nodes * width, 0.0);
  const double* f = grid.data();
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      for (std::size_t c = 0; c < width; ++c) {
        grid[(nodes + static_cast<std::size_t>(i) * n + j) * width + c] = edge_curvature(f, n, width, i, j, true, c);
        grid[(2 * nodes + static_cast<std::size_t>(j) * n + i) * width + c] = edge_curvature(f, n, width, i, j, false, c);
      }
}

}  // namespace pisco::detail
