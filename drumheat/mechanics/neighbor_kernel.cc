// Neighbour-list rebuild for CPU as one pass: an XLA FFI custom call (mechanics/cpu_kernel.py,
// `neighbor_pairs`), the C++ twin of drumheat.mechanics.neighbors.CellGrid.build followed by
// sort_pairs and the pair-identity search of remap_pair_data.
//
// It finds the same pairs as CellGrid.build, pair for pair, and writes them in the order of
// sort_pairs, so that a run is the same bit for bit whichever of the two builds it: by i (N+1) + j
// (the canonical order), or with `ranked` in the layout order of NeighborSetup.layout_order:
// grouped by the first particle i in the order of the particles' cells (CellGrid.order: by flat
// cell, by index within a cell), j ascending within a group (the order the C++ contact loop
// takes them in, contact_kernel.cc "Cell order"), unless the particles' own numbering keeps the
// pairs near enough in memory (numbering_will_do: then canonical, the order 0 .. N-1); padding
// N last. The same arithmetic in the same order as the JAX build:
//  * cell of a particle: floor(x_a / size_a) per axis in the dtype of the positions, clipped to
//    [0, cells_a) (wrapped along a periodic last axis); the flat cell c_0 + c_1 n_0 + c_2 n_0 n_1;
//  * visited cells: offsets -1, 0, 1 along axes of three or more cells (0 along the others),
//    wrapped modulo the cells of each axis (CellGrid.shifts / visit);
//  * a pair (i, j), i < j, is listed when |d|^2 < cutoff^2, d = x_j - x_i with the minimum image
//    dz - L rint(dz / L) along a periodic last axis, |d|^2 = (d_0^2 + d_1^2) + d_2^2, all in the
//    dtype of the positions;
//  * cell capacity: CellGrid.visit sees only the first `cap` particles (by index) of each cell
//    as the smaller partner; so here: a pair is listed only if its smaller index is among the
//    first `cap` of its cell. More than `cap` in a cell is flagged by the caller (fullest > cap)
//    and the chunk redone, as with the JAX build.
// Beyond the capacity M of the output the pairs are counted (total) but not written; the caller
// flags that overflow, and the list is not used.
//
// Inputs: 0 box-frame positions (N, D) f32 or f64; 1 the old pairs (2, M_old) s32 (padding N).
// Attributes: n0, n1, n2 cells per axis (n2 = 1 in 2D); s0, s1, s2 their sides (m); cut2 the
// squared cutoff; L the period of the last axis (0: none); cap the cell capacity; ranked (1: the
// pairs in the layout order, 0: canonical order).
// Outputs: 0 pairs (2, M) s32 in that order, padded with N (where M = M_old it may share input
// 1's buffer: the old pairs are then copied aside first); 1 for each new slot the old slot of
// the same pair, or -1 (new pair, padding); 2 pairs found (1) s32; 3 the most particles in one
// cell (1) s32; 4 the layout order (N) s32: the particles in the order of their cells, or
// 0 .. N-1 (the numbering will do, or not `ranked`).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <vector>
#include "kernel_math.h"
#include "kernel_team.h"
#include "xla/ffi/api/ffi.h"
namespace ffi = xla::ffi;

namespace {

using drumheat::Team;
using drumheat::team_size;

// floor(x / size) as XLA converts it to s32 (saturating, NaN -> 0), then clipped or wrapped
template <typename S>
inline int64_t cell_of(S x, S size, int64_t cells, bool wrap) {
  const S f = std::floor(x / size);
  int64_t c;
  if (!(f == f)) c = 0;
  else if (f >= S(2147483647.0)) c = 2147483647;
  else if (f <= S(-2147483648.0)) c = -2147483648LL;
  else c = static_cast<int64_t>(f);
  if (wrap) return ((c % cells) + cells) % cells;
  return c < 0 ? 0 : (c >= cells ? cells - 1 : c);
}

// Whether the particles' own numbering keeps the pairs (i, j) [0, w) of the list P (2, M) near
// enough in memory that the cell order (order: the particles by cell) is not worth its copies
// (NeighborSetup.layout_order, the same test): the pairs whose partners lie fewer than NEAR
// places apart, counted in the numbering and in the cell order; the numbering will do while it
// has at least half as many as the cell order.
constexpr int64_t NEAR = 256;

bool numbering_will_do(const int32_t* P, int64_t m, int64_t w, const int32_t* order, int64_t n) {
  std::vector<int32_t> rank(n);
  for (int64_t p = 0; p < n; ++p) rank[order[p]] = static_cast<int32_t>(p);
  int64_t near_numbering = 0, near_cells = 0;
  for (int64_t k = 0; k < w; ++k) {
    const int32_t i = P[k], j = P[m + k];
    near_numbering += std::abs(static_cast<int64_t>(j) - i) < NEAR;
    near_cells += std::abs(static_cast<int64_t>(rank[j]) - rank[i]) < NEAR;
  }
  return 2 * near_numbering >= near_cells;
}

struct Grid {
  int64_t cells[3];
  double size[3];
  double cut2, L;
  int64_t cap;
};

// Where the search puts its pairs: straight into the list (2, M), counting those beyond its
// capacity (the first part's), or into pairs of its own, (i, j) interleaved (the others',
// written after the first part's when all are done)
struct IntoList {
  int32_t* out;
  int64_t m, t = 0;
  void add(int32_t i, int32_t j) {
    if (t < m) { out[t] = i; out[m + t] = j; }
    ++t;
  }
};
struct Aside {
  std::vector<int32_t> pairs;
  void add(int32_t i, int32_t j) { pairs.push_back(i); pairs.push_back(j); }
};

// The search of build for the particles [lo, hi): their pairs (i, j), i < j, into `sink`, i
// ascending, j ascending for each i. A function of its own, not the team's lambda: with the
// lambda's captured references the compiler reloaded them in the inner loop.
template <typename S, int D, typename Sink>
void search(const S* x, int64_t lo, int64_t hi, const int64_t* coord, const int64_t* count,
            const int32_t* order, const int64_t* rank, const int64_t* shifts, int64_t ns,
            const int64_t* cells, int64_t cap, bool few, bool periodic, S cut2, S L,
            Sink& sink) {
  std::vector<int32_t> cand;
  for (int64_t i = lo; i < hi; ++i) {
    if (rank[i] >= cap) continue;  // not seen as the smaller partner (cell overflow)
    cand.clear();
    for (int64_t q = 0; q < ns; ++q) {
      int64_t k = 0, mult = 1;
      bool wrapped = few;
      for (int a = 0; a < D; ++a) {
        // the neighbour cell's coordinate modulo the cells of the axis: the cell's lies in
        // [0, cells) and the offset in {-1, 0, 1}, so one period at most (an integer division
        // per axis and offset took most of the build's time)
        int64_t c = coord[3*i + a] + shifts[3*q + a];
        if (a == D - 1) wrapped = wrapped || c < 0 || c >= cells[a];
        c = c < 0 ? c + cells[a] : (c >= cells[a] ? c - cells[a] : c);
        k += c * mult;
        mult *= cells[a];
      }
      const bool image = D == 3 && periodic && wrapped;
      for (int64_t u = count[k]; u < count[k + 1]; ++u) {
        const int32_t j = order[u];
        if (j <= i) continue;
        S d[D];
        for (int a = 0; a < D; ++a) d[a] = x[D*j + a] - x[D*i + a];
        if (image) d[D - 1] = d[D - 1] - L * drumheat::round_to_even(d[D - 1] / L);
        S r2 = d[0]*d[0] + d[1]*d[1];
        if (D == 3) r2 = r2 + d[2]*d[2];
        if (r2 < cut2) cand.push_back(j);
      }
    }
    std::sort(cand.begin(), cand.end());
    for (const int32_t j : cand) sink.add(static_cast<int32_t>(i), j);
  }
}

// particles per thread of the search at least (below: fewer threads)
constexpr int64_t MIN_PARTICLES = 2000;

// the pairs in canonical order into out (2, M), padded with N; the particles in the order of
// their cells into cell_order (N). The search for each particle's partners runs on the team's
// threads (kernel_team.h; C = the pool's threads, at most one per MIN_PARTICLES particles,
// DRUMHEAT_KERNEL_THREADS sets C), part c taking the particles [n c / C, n (c + 1) / C), the
// first into the list, the others into pairs of their own, written after it one part after
// the other: the list of one thread, slot for slot (the pairs of the parts after the first,
// 8 bytes each set aside, are the only memory the threads add to the build's).
template <typename S, int D>
void build(ffi::ThreadPool& pool, const S* x, int64_t n, const Grid& g, int32_t* out, int64_t m,
           int64_t* total, int64_t* fullest, int32_t* cell_order) {
  const int64_t nc = g.cells[0] * g.cells[1] * g.cells[2];
  const bool periodic = g.L > 0;
  const S size[3] = {S(g.size[0]), S(g.size[1]), S(g.size[2])};
  const S cut2 = S(g.cut2), L = S(g.L);
  std::vector<int64_t> coord(static_cast<size_t>(3 * n), 0), key(n), count(nc + 1, 0);
  for (int64_t p = 0; p < n; ++p) {
    int64_t k = 0, mult = 1;
    for (int a = 0; a < D; ++a) {
      const int64_t c = cell_of<S>(x[D*p + a], size[a], g.cells[a], periodic && a == D - 1);
      coord[3*p + a] = c;
      k += c * mult;
      mult *= g.cells[a];
    }
    key[p] = k;
    ++count[k + 1];
  }
  *fullest = 0;
  for (int64_t c = 0; c < nc; ++c) *fullest = std::max(*fullest, count[c + 1]);
  for (int64_t c = 0; c < nc; ++c) count[c + 1] += count[c];  // now the start of each cell
  std::vector<int32_t> order(n);
  std::vector<int64_t> fill(count.begin(), count.end() - 1), rank(n);
  for (int64_t p = 0; p < n; ++p) {  // stable: by index within a cell, as argsort(key)
    rank[p] = fill[key[p]] - count[key[p]];
    order[fill[key[p]]++] = static_cast<int32_t>(p);
  }
  // the visited offsets (CellGrid.shifts)
  std::vector<int64_t> shifts;
  for (int64_t a0 = -1; a0 <= 1; ++a0)
    for (int64_t a1 = -1; a1 <= 1; ++a1)
      for (int64_t a2 = -1; a2 <= 1; ++a2) {
        const int64_t s[3] = {a0, a1, a2};
        bool ok = true;
        for (int a = 0; a < 3; ++a)
          if (s[a] != 0 && (a >= D || g.cells[a] < 3)) ok = false;
        if (ok) shifts.insert(shifts.end(), s, s + 3);
      }
  const int64_t ns = static_cast<int64_t>(shifts.size() / 3);
  // the minimum image along the periodic axis changes nothing where the neighbour cell did
  // not wrap and the axis has five cells or more: then |dz| < 2 cells <= 0.4 L, dz / L rounds
  // to 0 and dz - L 0 is dz, bit for bit (the rounding for every pair cost 7 % of the build)
  const bool few = g.cells[D - 1] < 5;
  const int64_t nt = team_size(pool, n / MIN_PARTICLES, n);
  IntoList list{out, m};
  std::vector<Aside> aside(nt - 1);
  Team team(pool, nt);
  team.each([&](int part) {
    auto into = [&](auto& sink) {
      search<S, D>(x, n * part / nt, n * (part + 1) / nt, coord.data(), count.data(),
                   order.data(), rank.data(), shifts.data(), ns, g.cells, g.cap, few, periodic,
                   cut2, L, sink);
    };
    if (part == 0) into(list);
    else into(aside[part - 1]);
  });
  for (Aside& a : aside) {
    for (size_t u = 0; u < a.pairs.size(); u += 2) list.add(a.pairs[u], a.pairs[u + 1]);
    std::vector<int32_t>().swap(a.pairs);
  }
  const int64_t t = list.t;
  for (int64_t k = t; k < m; ++k) out[k] = out[m + k] = static_cast<int32_t>(n);  // padding
  *total = t;
  std::copy(order.begin(), order.end(), cell_order);
}

// With `ranked`, the canonical pairs out (2, M) (w of them written) and their sources src
// regrouped in the cell order (cell_order), unless the numbering will do: then cell_order
// becomes 0 .. N-1.
void regroup(bool ranked, int32_t* out, int32_t* src, int64_t m, int64_t w, int32_t* cell_order,
             int64_t n) {
  if (!ranked || numbering_will_do(out, m, w, cell_order, n)) {
    for (int64_t p = 0; p < n; ++p) cell_order[p] = static_cast<int32_t>(p);  // the numbering's
    return;
  }
  std::vector<int64_t> start(n + 1, 0);  // each particle's first slot
  for (int64_t k = 0; k < w; ++k) ++start[out[k] + 1];
  for (int64_t p = 0; p < n; ++p) start[p + 1] += start[p];
  std::vector<int32_t> oldi(out, out + w), oldj(out + m, out + m + w), olds(src, src + w);
  int64_t k = 0;
  for (int64_t p = 0; p < n; ++p) {
    const int32_t i = cell_order[p];
    for (int64_t u = start[i]; u < start[i + 1]; ++u, ++k) {
      out[k] = oldi[u];
      out[m + k] = oldj[u];
      src[k] = olds[u];
    }
  }
}

// for each new slot, the old slot of the same pair or -1 (remap_pair_data's search). The lists
// made here hold each first particle's pairs together (in either order of build): each
// particle's run of old slots is found in one pass and searched for j. An old list not so
// grouped (not made here) is searched by its sorted keys i (N+1) + j instead.
void sources(const int32_t* old, int64_t mo, const int32_t* nw, int64_t m, int64_t n,
             int32_t* src) {
  std::vector<int64_t> first(n, -1), past(n, -1);  // particle i's old slots [first, past)
  bool grouped = true;
  for (int64_t k = 0; k < mo && grouped; ++k) {
    const int32_t i = old[k];
    if (i < 0 || i >= n) continue;  // padding
    if (first[i] < 0) { first[i] = k; past[i] = k + 1; }
    else if (past[i] == k) past[i] = k + 1;
    else grouped = false;
  }
  if (grouped) {
    for (int64_t k = 0; k < m; ++k) {
      src[k] = -1;
      const int32_t i = nw[k], j = nw[m + k];
      if (i < 0 || i >= n) continue;
      for (int64_t u = first[i]; u >= 0 && u < past[i]; ++u)
        if (old[mo + u] == j) { src[k] = static_cast<int32_t>(u); break; }
    }
    return;
  }
  auto key = [n](int32_t i, int32_t j) { return static_cast<int64_t>(i) * (n + 1) + j; };
  std::vector<int64_t> ko(mo);
  std::vector<int32_t> perm(mo);
  for (int64_t k = 0; k < mo; ++k) {
    ko[k] = key(old[k], old[mo + k]);
    perm[k] = static_cast<int32_t>(k);
  }
  std::stable_sort(perm.begin(), perm.end(), [&](int32_t a, int32_t b) { return ko[a] < ko[b]; });
  std::vector<int64_t> ks(mo);
  for (int64_t k = 0; k < mo; ++k) ks[k] = ko[perm[k]];
  for (int64_t k = 0; k < m; ++k) {
    src[k] = -1;
    if (nw[k] >= n) continue;
    const int64_t kn = key(nw[k], nw[m + k]);
    const auto it = std::lower_bound(ks.begin(), ks.end(), kn);
    if (it != ks.end() && *it == kn) src[k] = perm[it - ks.begin()];
  }
}

}  // namespace

static ffi::Error NeighborsImpl(ffi::ThreadPool pool, ffi::AnyBuffer pos, ffi::Buffer<ffi::S32> old, int64_t n0,
                                int64_t n1, int64_t n2, double s0, double s1, double s2,
                                double cut2, double L, int64_t cap, int32_t ranked,
                                ffi::ResultBuffer<ffi::S32> pairs,
                                ffi::ResultBuffer<ffi::S32> src,
                                ffi::ResultBuffer<ffi::S32> total,
                                ffi::ResultBuffer<ffi::S32> fullest,
                                ffi::ResultBuffer<ffi::S32> cell_order) {
  const auto pd = pos.dimensions();
  if (pd.size() != 2 || (pd[1] != 2 && pd[1] != 3))
    return ffi::Error::InvalidArgument("drumheat_neighbors: positions must be (N, 2) or (N, 3)");
  const int64_t n = pd[0], m = pairs->dimensions()[1], mo = old.dimensions()[1];
  if (n0 < 1 || n1 < 1 || n2 < 1)
    return ffi::Error::InvalidArgument("drumheat_neighbors: cells per axis must be positive");
  const Grid g{{n0, n1, n2}, {s0, s1, s2}, cut2, L, cap};
  int64_t t = 0, f = 0;
  int32_t* out = pairs->typed_data();
  int32_t* co = cell_order->typed_data();
  const bool f64 = pos.element_type() == ffi::DataType::F64;
  if (!f64 && pos.element_type() != ffi::DataType::F32)
    return ffi::Error::InvalidArgument("drumheat_neighbors: positions must be f32 or f64");
  // the new list may take the old one's buffer (an XLA alias, cpu_kernel.neighbor_pairs):
  // then the old pairs are kept aside until their sources are found
  const int32_t* op = old.typed_data();
  std::vector<int32_t> kept;
  if (static_cast<const void*>(op) == static_cast<const void*>(out)) {
    kept.assign(op, op + 2 * mo);
    op = kept.data();
  }
  const void* xp = pos.untyped_data();
  if (pd[1] == 3) {
    if (f64) build<double, 3>(pool, static_cast<const double*>(xp), n, g, out, m, &t, &f, co);
    else build<float, 3>(pool, static_cast<const float*>(xp), n, g, out, m, &t, &f, co);
  } else {
    if (f64) build<double, 2>(pool, static_cast<const double*>(xp), n, g, out, m, &t, &f, co);
    else build<float, 2>(pool, static_cast<const float*>(xp), n, g, out, m, &t, &f, co);
  }
  // the sources of the canonical list (the old one's groups searched by i), then both regrouped
  sources(op, mo, out, m, n, src->typed_data());
  std::vector<int32_t>().swap(kept);
  regroup(ranked != 0, out, src->typed_data(), m, std::min(t, m), co, n);
  const int64_t big = std::numeric_limits<int32_t>::max();
  total->typed_data()[0] = static_cast<int32_t>(std::min(t, big));
  fullest->typed_data()[0] = static_cast<int32_t>(std::min(f, big));
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    Neighbors, NeighborsImpl,
    ffi::Ffi::Bind()
        .Ctx<ffi::ThreadPool>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::Buffer<ffi::S32>>()
        .Attr<int64_t>("n0").Attr<int64_t>("n1").Attr<int64_t>("n2")
        .Attr<double>("s0").Attr<double>("s1").Attr<double>("s2")
        .Attr<double>("cut2").Attr<double>("L").Attr<int64_t>("cap").Attr<int32_t>("ranked")
        .Ret<ffi::Buffer<ffi::S32>>().Ret<ffi::Buffer<ffi::S32>>()
        .Ret<ffi::Buffer<ffi::S32>>().Ret<ffi::Buffer<ffi::S32>>()
        .Ret<ffi::Buffer<ffi::S32>>());

// Per-pair data carried to the rebuilt list in its own buffer (cpu_kernel.take_pair_data_in_place,
// the twin of neighbors.take_pair_data): row k of the result is row src[k] of the data, or zeros
// where src[k] < 0 (a new pair, padding). The data are moved as raw words of their element size,
// one column at a time through a scratch column (M words), so that a rebuild holds one column
// beside the list instead of a second copy of every per-pair array.
//
// Inputs: 0 the sources (M,) s32 (the rebuild's output 1); 1 the data (M, ...) of any type.
// Output: 0 the data (M, ...) of that type, aliased to input 1.
namespace {

template <typename W>
void take_rows(const W* in, W* out, const int32_t* src, int64_t m, int64_t c) {
  if (in != out) {  // not aliased: gather straight across
    for (int64_t k = 0; k < m; ++k)
      for (int64_t q = 0; q < c; ++q) out[k * c + q] = src[k] >= 0 ? in[src[k] * c + q] : W(0);
    return;
  }
  std::vector<W> col(static_cast<size_t>(m));
  for (int64_t q = 0; q < c; ++q) {
    for (int64_t k = 0; k < m; ++k) col[k] = out[k * c + q];
    for (int64_t k = 0; k < m; ++k) out[k * c + q] = src[k] >= 0 ? col[src[k]] : W(0);
  }
}

}  // namespace

static ffi::Error TakePairsImpl(ffi::Buffer<ffi::S32> src, ffi::AnyBuffer data,
                                ffi::Result<ffi::AnyBuffer> out) {
  const auto dd = data.dimensions();
  const int64_t m = src.dimensions()[0];
  if (dd.size() < 1 || dd[0] != m)
    return ffi::Error::InvalidArgument("drumheat_take_pairs: the data must have one row per slot");
  int64_t c = 1;
  for (size_t a = 1; a < dd.size(); ++a) c *= dd[a];
  const int32_t* s = src.typed_data();
  for (int64_t k = 0; k < m; ++k)
    if (s[k] >= m)
      return ffi::Error::InvalidArgument("drumheat_take_pairs: a source beyond the list");
  const size_t bytes = ffi::ByteWidth(data.element_type());
  void* o = out->untyped_data();
  const void* i = data.untyped_data();
  if (m * c == 0) return ffi::Error::Success();
  switch (bytes) {
    case 1: take_rows(static_cast<const uint8_t*>(i), static_cast<uint8_t*>(o), s, m, c); break;
    case 2: take_rows(static_cast<const uint16_t*>(i), static_cast<uint16_t*>(o), s, m, c); break;
    case 4: take_rows(static_cast<const uint32_t*>(i), static_cast<uint32_t*>(o), s, m, c); break;
    case 8: take_rows(static_cast<const uint64_t*>(i), static_cast<uint64_t*>(o), s, m, c); break;
    default:
      return ffi::Error::InvalidArgument("drumheat_take_pairs: elements of 1, 2, 4 or 8 bytes");
  }
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    TakePairs, TakePairsImpl,
    ffi::Ffi::Bind().Arg<ffi::Buffer<ffi::S32>>().Arg<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>());
