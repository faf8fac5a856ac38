// DEM contact kernel for CPU as one loop: an XLA FFI custom call (mechanics/cpu_kernel.py).
//
// The contact law is the one of drumheat.mechanics.contact_forces, read in `contact` and
// `rolling` below (one place each):
//  * contact_law: linear spring-dashpot normal force clipped at zero, Cundall-Strack tangential
//    spring rotated onto the tangent plane, Coulomb cap, tangential dashpot only while sticking
//    (Weigler digest, shared/reference/weigler-thermal-dem.md sec. 4 [2.1]-[2.4] and sec. 5;
//    shared/peers/liggghts/README.md "hooke" with tangential history);
//  * rolling_torque: constant directional torque M = -min(mu_r R* F_n, I* |w_rel| / dt)
//    w_rel / |w_rel| (Ai et al. 2011 "model A", capped so that it cannot reverse w_rel).
// for the particle-particle pairs and the particle-wall contacts (the wall geometry is evaluated
// in JAX and comes in as distance, unit normal and wall velocity per particle and wall, except a
// drum shell's, which the loop computes itself: input 22; a wall is partner A with infinite
// mass, no radius, spin omega_wall about z).
//
// Scope: 3D (positions, velocities, spins (N, 3)) and 2D (a monolayer of spheres: positions and
// velocities (N, 2) in x-y, spin (N) about z, torque a_x f_y - a_y f_x, as cross_w_a / cross_a_f
// of contact_forces.py); float32 or float64 mechanics (one template instance per dtype and
// dimension, chosen at run time from the buffers); several materials: per-pair parameters from
// the particle-particle tables (T, T) and per particle-wall slot from the tables (T, W), indexed
// by the particle types; an optional periodic last axis (3D).
//
// The new pair and wall springs may share their buffers with the old ones (cpu_kernel.py aliases
// them): each slot reads its old spring before it writes the new one, and nothing else.
//
// Inputs (S = float or double):
//   0 positions (N, D) S      1 velocities (N, D) S    2 spins (N, 3) or (N) S
//   3 radii (N) S             4 masses (N) S           5 moments of inertia (N) S
//   6 particle types (N) s32  7 pairs (2, M) s32, padding N
//   8 pair springs (M, D) S
//   9 wall distance (N, W') S  10 wall normal, from the wall to the particle (N, W', D) S
//  11 wall velocity at the particle (N, W', D) S      12 wall springs (N, W, D) S
//     (W' = W, or W - 1 with a drum shell, input 22: the walls 1 .. W - 1)
//  13 particle-particle tables (6, T, T) S: kn, kt, zeta_n, zeta_t, mu, mu_roll
//  14 particle-wall tables (6, T, W) S: the same per particle type and wall
//  15 wall angular velocities about z (W) S          16 temperatures (N or 0) f64
//  17 wall distance before the step (N, W) S (friction heat; else length 0)
//  18 the particles in the order of their cells (N) s32 (a permutation), or length 0
//  19 body force (N, D) or (1, D) S, one row for every particle (gravity m g), or length 0
//  20 the coming step's skin test (see below): c, dt, L, 1 / L, lo_0 .. lo_{D-1} (4 + D) S,
//     or length 0; 21 the neighbour list's reference positions (N, D) S (with 20)
//  22 the drum shell (2) S: radius R and angular velocity omega of wall 0, a cylinder about
//     the z axis (geometry.walls.DrumShell), whose geometry the loop computes (below); or
//     length 0: every wall's geometry given (inputs 9-11)
//  23 the step's kicks and drift (below): a, c, c_I, dt, L (5) S, or length 0; 24 the forces
//     and 25 the torques of the step before (N, D) and (N, 3) or (N) S (with 23)
//  26 a run of steps (below): K, the most steps, and half the skin squared (2) S, or length 0
//     (one step; with 26 also 20, 21, 23 and, with walls, the flags of output 16)
// Attributes: dt, L (period of the last axis, 0 = none), law (conduction, < 0 = none), h
// (its coefficient), tol (conduction gap tolerance), rot (0: no torques, no rolling), fh
// (1: friction heat), cgap (the gap tolerance of output 11), wgap (that of output 16).
// Outputs: 0 forces (N, D): the contacts' sum plus the body force (input 19, added last),
// 1 torques (N, 3) or (N); 2 new pair springs (M, D); 3 overlap, 4 centre distance, 5 normal
// force per pair (M, or all three of length 0: not written, for a caller that reads none of
// them); 6 new wall springs (N, W, D); 7 overlap and 8 normal force per wall slot (N, W)
// (all zero where nothing touches); 9 the largest overlap / radius (smaller radius of a pair)
// (1); 10 heat flow into each particle (N or 0) f64;
// 11 whether each pair conducts (M) pred: it overlaps, or its surface gap |d| - r_i - r_j is at
// most cgap min(d_i, d_j) (the pair_conducts of forces.ContactForces.pair_gap_mask); friction
// heat (length 0 without fh): 12 pair rows (M, KP) S, 13 wall rows (N W, KW) S, 14 the losses
// at the continuous rates (3) f64; 15 the coming step's largest squared displacement (1) S
// (length 0 without input 20); 16 whether each wall slot conducts (N, W) pred: it touches, or
// with wgap > 0 its overlap r - d is at least -wgap 2 r (the wall_gap_mask of
// forces.ContactForces), or length 0 (not written); with input 23 (else length 0 each) 17 the
// positions, 18 the velocities and 19 the spins after the step's kicks and drift, at which the
// call computes the contacts (cpu_kernel.py aliases them with inputs 0-2, and the forces and
// torques, outputs 0-1, with inputs 24-25: updated in place; the loop reads 24-25 only in the
// pass that packs the records, before it sums a force, and in a run of steps a particle's
// force and torque in the pass that sums them, after it has); with input 26 (else length 0
// each) 20
// each pair slot's (M) and 21 each wall slot's (N W) count of the steps it conducted (the flags
// of outputs 11 and 16 summed over the run's steps) s32 and 22 the steps made (1) s32.
//
// A run of steps (input 26; integrator.run_segments with a counting hook, the coupled heat's):
// after the call's step, while fewer than K steps are made and the coming step's skin test
// (output 15) is at most half the skin squared, the loop makes the next step as the next call
// would: from this step's positions, half-step velocities and spins (outputs 17-19), forces
// and torques (0-1) and springs (2, 6), its pending half-kick's factor a = 1. The steps between
// two of the coupled heat's thermal steps need of the contacts only which ones conduct, so the
// run hands back their counts (outputs 20-21); every other output is that of the last step but
// output 9, the largest overlap ratio of all steps. The same numbers as one call per step:
// each step's arithmetic is the call's, and the counts are integers. The loop's caller (XLA)
// then returns only at a thermal step, a rebuild or the end of a chunk. The steps share what
// depends only on the list (the chunks, the cell order's layout: Shared), the threads (Team)
// and their buffers (the records, the chunks' accumulators: Carry), and a step after the first
// leaves the padding slots' outputs as the first wrote them (the same buffers). A step that
// another may follow makes that step's kicks and drift in the pass that adds its own forces,
// for each particle as soon as its force and torque are summed, into the records (Carry): the
// coming step has no packing pass (which read each particle's x, v, w, F and M at its index
// and wrote x', v', w' back there), and writes its x',
// v', w' out (outputs 17-19) in its own sum pass; that pass also zeroes the accumulators it
// has read, for the coming step (no memset of them). Where the skin test then ends the run,
// the coming step's records go unused; the outputs are the step's.
//
// The step's kicks and drift (inputs 23-25; integrator.run_segments): the positions, velocities
// and spins given are those of the step before, the velocities and spins at its half step with
// a times its last half-kick pending (a = 0 or 1), F and M its forces and torques. The call
// first does what the loop did in XLA before it, for particles of one mass and one moment of
// inertia: v' = fma(F, c, fma(a F, c, v)) (the pending half-kick and the step's first one,
// c = dt / (2 m)), w' = fma(M, c_I, fma(a M, c_I, w)) with rotation (c_I = dt / (2 I); else
// w' = w), x' = fma(v', dt, x) with the periodic last axis (L > 0) brought back into [0, L) by
// one period: the roundings of XLA's code for integrator.run_segments' kicks and drift on
// x86-64 (it fuses each product and sum into a multiply-add and folds (dt / 2) (1 / m) into
// one constant); then the contacts at x', v', w' as if they had been given. It runs in the pass
// that packs the particles' records (the one pass that reads them), where XLA made three passes
// over the particles and wrote them out for the loop to read back; in a run of steps, for
// every step after the first, in the step before's sum pass (above). The walls' geometry is then
// the loop's own (no walls, or the drum shell alone, input 22): JAX's would be that of the
// positions before the drift.
//
// The drum shell (input 22; geometry.walls.DrumShell.evaluate): from the particle's x, y,
// rho = sqrt(x^2 + y^2), the distance R - rho, the unit normal -e_rho with e_rho = (x, y) / rho
// ((1, 0) where rho <= 1e-30) and the wall velocity omega e_z x (R e_rho), z components 0, with
// the roundings of XLA's code for evaluate on x86-64: x^2 + y^2 as fma(x, x, y^2) (its code
// generator fuses the sum so) and the quotient as (x, y) (1 / rho) (its simplifier turns a
// quotient by one value per row into a product with the reciprocal); where XLA's code does not
// fuse, the distance may differ by an ulp. The loop reads the positions anyway; in XLA the
// shell's geometry was four passes over the particles per step, written out as (N, D) arrays
// for the loop to read back.
//
// The coming step's skin test (inputs 20, 21; integrator.run_segments): the loop that steps
// between neighbour rebuilds tests, before each step, whether the step's drift takes a particle
// more than half the skin from where the list was built. The velocities of this call are the
// half-step ones; with the forces F of the call (body force included) the coming step's are
// v' = (v + c F) + c F (this step's second half-kick and the coming step's first, c = dt / (2 m)
// for particles of one mass), its positions x' = x + dt v' with the periodic last axis (L > 0)
// brought back into [0, L) by one period, and output 15 is the largest |x' - lo - x_ref|^2
// (minimum image along the periodic axis, dz - L round(dz / L), the rounding to even as
// jnp.round, with dz / L taken as dz (1 / L) as XLA computes it): the arithmetic of the
// loop's condition in XLA (the same velocities, positions and displacements; the sum of the
// squares may differ by an ulp where XLA's code fuses it into multiply-adds), in the pass
// that adds the chunks' forces, where F is at hand. Its kicks and drift are not fused into
// multiply-adds, where the step's own with input 23 are (as XLA's code in the loop fuses them):
// where the coming step drifts in the call, its largest displacement may differ from this
// test's by an ulp, which changes a rebuild only where one lies within an ulp of half the skin
// (the skin test is a bound with a margin of the skin, not a part of the trajectory).
//
// Contact conduction (optional, law >= 0; drumheat/mechanics/conduction.py): the heat flow into
// each particle Q_i = sum_j g_ij (T_j - T_i) over the conducting pairs, g = h pi min(r_i, r_j)^2
// (law 0, "projected": Weigler digest eq. [2.7] with A_p = pi d^2 / 4 of the smaller sphere) or
// g = h sqrt(A_c) with A_c the area of the overlap circle (law 1, "overlap": LIGGGHTS
// heat/gran/conduction; zero for a pair that does not overlap). A pair conducts when it
// overlaps, or with tol > 0 when its surface gap L - r_i - r_j is at most tol min(d_i, d_j)
// (the gap tolerance of drumheat.thermal.network.find_contacts_2d_drum). With law < 0, the
// temperatures and Q have length 0.
//
// Friction heat (optional, fh = 1; drumheat/mechanics/dissipation.py): each contact's loss in
// the step D = -dt (F . u + M_r . w_rel) - (U_new - U_old) needs the full-step velocities, which
// exist only after the forces of all contacts are summed and the second half-kick is done. So
// the loop writes one row per contact, KP = 3 D + DW + 1 values for a pair (the force F on j,
// the levers a_i, a_j, the rolling torque M_r on j and U_new - U_old) and KW = 2 D + DW + 1 for
// a wall slot (F, the lever, M_r, U_new - U_old), U = k_n delta^2 / 2 (while delta > 0) +
// k_t |xi|^2 / 2 with the overlap before the step from the positions x - dt v (pairs) or the
// wall distance before the step (input 17); a slot that does not touch has only -U_old, its
// springs' energy, which the model discards. The loss rates by source (contact_law with
// dissipation=True: damping, sliding; rolling_loss) are summed over all contacts (output 14).
// The second pass, ContactHeat (cpu_kernel.contact_heat), takes the rows and the full-step
// velocities and spins and gives each contact's D to its partners as step_heat does: particle
// A gets k_A / (k_A + k_B) D and B the rest (conductivities (N) f64; length 0: half and half),
// a wall contact's particle k_p / (k_p + k_w) D with the walls' k_w (attribute kw), the rest is
// the walls'. ContactHeat's inputs: 0 velocities (N, D) S, 1 spins (N, 3) or (N) S, 2 pairs
// (2, M) s32, 3 pair rows (M, KP) S, 4 wall rows (N W, KW) S, 5 wall velocity (N, W, D) S, 6
// wall angular velocities (W) S, 7 conductivities (N or 0) f64, 8 the cell order (N or 0) s32
// (input 18 of Contacts: the chunks are cut as there); attributes dt, kw; outputs 0 the heat of
// each particle (N) f64, 1 the walls' and all contacts' (2) f64, J.
//
// The coupled heat's contact conduction (CountConduction; cpu_kernel.count_conduction, for
// drumheat.thermal.contact.ContactConduction in the coupled DEM's thermal step): the heat flow
// into each particle Q_i = sum over the pair slots of g (c dt / h) (T_j - T_i), added at i and
// taken from j, g = alpha pi min(r_i, r_j)^2 of law 0 above (`conductance`, r = d / 2), c the
// slot's count of the DEM steps of length dt it conducted during the thermal step h (output 20
// summed over the thermal step's runs); slots with c = 0 add 0 and those with a padding index
// (>= N) nothing. One pass over the slots in their order, on the calling thread (split in
// the contact pass's chunks on two threads it took longer: XLA runs the thermal step's other
// work beside it); the fraction as c (dt / h), dt / h computed once, as XLA computes the JAX
// sum's (c dt) / h. Inputs: 0 temperatures (N) f64, 1 diameters (N) f64, 2 alpha (1) f64, 3
// pairs (2, M) s32 (the neighbour list itself: its rows as two arrays were copies), 4 counts
// (M) s32; attributes dt, h; output 0 Q (N) f64, W.
//
// Cell order (input 18): the loop reads both partners' data for every listed pair, so where the
// particles' numbering has no relation to their places (a bed that has mixed for a while, see
// docs/performance.md) nearly every pair misses the cache twice. The neighbour build then lists
// the pairs grouped by their first particle in the order of the particles' cells
// (NeighborList.order, neighbor_kernel.cc `ranked`), and given that order the loop first copies
// the positions, velocities, spins, radii, masses, moments of inertia and temperatures into it,
// looks up each partner's rank, sums the forces, torques and heat at the ranks and puts the sums
// back in the particles' numbering at the end: consecutive pairs and both partners of a pair
// then lie near each other in memory, however the particles are numbered. Each sum takes its
// terms in the list's order, as without the order; the per-slot arrays and the particle types
// stay in the particles' numbering. (Laying the data out in the cell order alone, with the
// pairs taken in the order of the numbering, gained nothing: docs/performance.md.) An order
// 0 .. N-1, which the build gives while the particles' own numbering keeps neighbours near in
// memory (NeighborSetup.layout_order), means no reordering: the loop runs as without an order.
//
// Threads: the pair slots are cut into C chunks, C = the threads of XLA's intra-op pool, at
// most one per MIN_CHUNK listed pairs (DRUMHEAT_KERNEL_THREADS sets C): chunk c takes the
// groups of the particles (indices, or ranks in the cell order) from the first particle of the
// listed pair listed c / C on (the pairs come sorted by i or grouped in the cell order, padding
// last, as neighbors.sort_pairs leaves them; any other list is computed right, in uneven
// chunks: see `chunks`), the wall slots of the particles of index range c of C equal ones and
// an equal share of the padding slots (whose outputs are only zeroed); the passes over the
// particles take C equal ranges. Cut by listed pairs in whole particles' groups, the chunks
// share the pair work evenly however many padding slots the list has (cut by slots, the first
// chunk took nearly all the pairs of a list half padding) and however unevenly the pairs fall
// on the particles (cut in equal particle ranges, the built-in drum's first chunk took 53 % of
// the pairs and ran 15-18 % longer than the second); a pair's chunk does not depend on the
// list's capacity, but on its listed pairs (its skin, and where it was built): the sums of
// the chunks meet at other particles, round-off. Both passes (Contacts and ContactHeat) cut their
// chunks so. The passes of a call are made by one Team (kernel_team.h, which the neighbour
// build's search uses too): its C - 1 pool threads stay with the call, waiting between the
// passes, and the calling thread takes any chunk no pool thread has started (handed each pass
// anew, the pool thread began the contact pass some 40 us after it was handed over, on
// average, and the pass that adds the sums mostly only after the calling thread had made both
// chunks). Chunk c accumulates its forces (and the second pass its heat) in its own buffer and
// the buffers are summed in chunk order, so the result depends on C and the list (round-off)
// and on nothing else, whichever thread ran which chunk.
//
// Records: each call first copies the particles' positions and radii, and their velocities,
// spins, masses and moments of inertia, into one record per particle each (pack_particles; 12
// values per particle, in a buffer that lives across calls; in the cell order where there is
// one: this copy is the one that lays the data out), so that the pair loop reads a partner's
// data from one cache line instead of from one per array; a run's later steps get theirs from
// the sum pass of the step before (a run of steps, above).
//
// Vector instructions: a chunk takes its pair slots in blocks of 256; within_reach tells which
// lie within reach, Loop::tile gathers those 64 at a time into a Tile (one array per quantity)
// and pair_law_tile computes their contact law in one loop without branches, which the compiler
// turns into vector instructions (with GCC on x86-64 in AVX-512, AVX2 and baseline versions,
// the processor's chosen when the library is loaded). The results are added slot by slot in the
// list's order, and every version computes the same roundings (cpu_kernel.FLAGS), so the numbers
// do not depend on the version.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>
#include "kernel_math.h"
#include "kernel_team.h"
#include "xla/ffi/api/ffi.h"
namespace ffi = xla::ffi;

namespace {

using drumheat::Team;
using drumheat::team_size;

constexpr int64_t MIN_CHUNK = 8000;  // listed pairs per chunk at least (below: one thread)
constexpr double kPi = 3.14159265358979323846;
constexpr int kTables = 6;  // kn, kt, zeta_n, zeta_t, mu, mu_roll

// the parameters of one material pair (one entry of the contact tables); gn = 2 zeta_n sqrt(k_n)
// and gt = 2 zeta_t sqrt(k_t), the dashpots' factors of sqrt(m*) (computed once here, the same
// numbers as in the law: (2 zeta) sqrt(k) is the product's first two factors there too)
template <typename S>
struct Law {
  S kn, kt, gn, gt, mu, mur;
};

// tables (6, A, B) -> A * B laws
template <typename S>
std::vector<Law<S>> laws(const S* tab, int64_t a, int64_t b) {
  const int64_t ab = a * b;
  std::vector<Law<S>> out(ab);
  for (int64_t q = 0; q < ab; ++q) {
    const S kn = tab[q], kt = tab[ab + q];
    out[q] = Law<S>{kn, kt, S(2)*tab[2*ab + q]*std::sqrt(kn), S(2)*tab[3*ab + q]*std::sqrt(kt),
                    tab[4*ab + q], tab[5*ab + q]};
  }
  return out;
}

template <typename S, int D>
inline S dot(const S* a, const S* b) {
  S s = a[0]*b[0] + a[1]*b[1];
  if constexpr (D == 3) s += a[2]*b[2];
  return s;
}

// contact_forces.contact_law for one contact between partner A and partner B: unit normal n
// from A to B, overlap ov > 0, relative velocity vr of B's contact point against A's, effective
// mass me, old spring so. Writes the new spring to s (which may be so: the springs are updated
// in place) and returns the normal force F_n; f receives the force on B. With loss (friction
// heat) loss[0] = the dashpots' loss and loss[1] = the Coulomb limit's of the step (0 while
// sticking), J (contact_law(dissipation=True): damping_loss, slip_loss).
// Without branches on the numbers (both the sliding and the sticking force are computed and one
// is selected; a quotient that a branch would have skipped may be inf or NaN and is never
// selected): no mispredicted branch per contact, and the compiler can run a loop of contacts in
// vector instructions (pair_law_tile); every selected number is computed as before.
template <typename S, int D>
inline S contact(const Law<S>& c, S dt, const S* n, S ov, const S* vr, S me, const S* so, S* s,
                 S* f, S* loss = nullptr) {
  const S sqm = std::sqrt(me);
  const S vn = dot<S, D>(vr, n);  // > 0: separating
  S fn = c.kn*ov - c.gn*sqm*vn;  // k_n delta + gamma_n d(delta)/dt
  fn = fn < S(0) ? S(0) : fn;  // never attractive
  S vt[D], xp[D], x[D], fs[D], ft[D], slip[D];
  for (int a = 0; a < D; ++a) vt[a] = vr[a] - vn*n[a];
  // rotate the old spring onto the current tangent plane, keeping its length
  const S xin = dot<S, D>(so, n);
  for (int a = 0; a < D; ++a) xp[a] = so[a] - xin*n[a];
  const S lo = std::sqrt(dot<S, D>(so, so));
  const S lp = std::sqrt(dot<S, D>(xp, xp));
  const S q = lo / lp;
  const S sc = lp > S(0) ? q : S(1);
  for (int a = 0; a < D; ++a) { x[a] = xp[a]*sc + vt[a]*dt; fs[a] = -c.kt*x[a]; }
  const S fl = std::sqrt(dot<S, D>(fs, fs));
  const S fc = c.mu*fn;
  // sliding (fl > fc): the spring is kept at the Coulomb limit, no tangential dashpot
  const bool slide = fl > fc;
  const S ratio = fc / fl;
  const S gt = c.gt*sqm;
  for (int a = 0; a < D; ++a) {
    const S fsl = fs[a]*ratio;
    const S xl = -fsl/c.kt;
    slip[a] = x[a] - xl;
    ft[a] = slide ? fsl : fs[a] - gt*vt[a];
    x[a] = slide ? xl : x[a];
  }
  if (loss) {
    const S damped = (c.kn*ov - fn)*vn;
    const S sliding = damped*dt, sticking = (damped + gt*dot<S, D>(vt, vt))*dt;
    const S slipped = fc*std::sqrt(dot<S, D>(slip, slip));
    loss[0] = slide ? sliding : sticking;
    loss[1] = slide ? slipped : S(0);
  }
  for (int a = 0; a < D; ++a) { s[a] = x[a]; f[a] = fn*n[a] + ft[a]; }  // so not read after
  return fn;
}

// contact_forces.rolling_torque: the rolling-resistance torque M on partner B for the relative
// spin w = w_B - w_A (a 3-vector in 3D, the z component in 2D)
template <typename S, int DW>
inline void rolling(const S* w, S fn, S reff, S mur, S ieff, S dt, S* M) {
  if constexpr (DW == 1) {
    const S mag = std::abs(w[0]);
    const S a = mur*reff*fn, b = ieff*mag/dt;
    const S cap = a < b ? a : b;
    M[0] = -cap * (w[0] > S(0) ? S(1) : (w[0] < S(0) ? S(-1) : S(0)));
  } else {
    const S mag = std::sqrt(w[0]*w[0] + w[1]*w[1] + w[2]*w[2]);
    const S a = mur*reff*fn, b = ieff*mag/dt;
    const S cap = a < b ? a : b;
    const S k = cap / (mag > S(0) ? mag : S(1));
    M[0] = -(k*w[0]); M[1] = -(k*w[1]); M[2] = -(k*w[2]);
  }
}

// contact_forces.rolling_loss: the energy the rolling torque M takes from the relative spin w
// in one step, |M| dt max(|w| - |M| dt / (2 I*), 0), J
template <typename S, int DW>
inline S rolling_loss(const S* M, const S* w, S ieff, S dt) {
  S mm = M[0]*M[0], ww = w[0]*w[0];
  if constexpr (DW == 3) { mm += M[1]*M[1] + M[2]*M[2]; ww += w[1]*w[1] + w[2]*w[2]; }
  const S m = std::sqrt(mm), rest = std::sqrt(ww) - S(0.5)*m*dt/ieff;
  return m*dt*(rest > S(0) ? rest : S(0));
}

// w x a: a 3-vector in 3D; in 2D w is the z component: w e_z x a = w (-a_y, a_x)
template <typename S, int D>
inline void spin_cross(const S* w, const S* a, S* out) {
  if constexpr (D == 3) {
    out[0] = w[1]*a[2] - w[2]*a[1];
    out[1] = w[2]*a[0] - w[0]*a[2];
    out[2] = w[0]*a[1] - w[1]*a[0];
  } else {
    out[0] = -w[0]*a[1];
    out[1] = w[0]*a[0];
  }
}

// out = sign (a x f): a 3-vector in 3D, the z component in 2D
template <typename S, int D>
inline void torque(const S* a, const S* f, S sign, S* out) {
  if constexpr (D == 3) {
    out[0] = sign*(a[1]*f[2] - a[2]*f[1]);
    out[1] = sign*(a[2]*f[0] - a[0]*f[2]);
    out[2] = sign*(a[0]*f[1] - a[1]*f[0]);
  } else {
    out[0] = sign*(a[0]*f[1] - a[1]*f[0]);
  }
}

// T += sign (a x f)
template <typename S, int D>
inline void add_torque(S* T, const S* a, const S* f, S sign) {
  constexpr int DW = D == 3 ? 3 : 1;
  S t[DW];
  torque<S, D>(a, f, sign, t);
  for (int c = 0; c < DW; ++c) T[c] += t[c];
}

// a spring set to zero, written only where it is not all zero bits already (most slots touch
// nothing and hold zeros: a read instead of a write-back of every cache line)
template <typename S, int D>
inline void clear(S* s) {
  using U = std::conditional_t<sizeof(S) == 8, uint64_t, uint32_t>;  // the bits (-0 is not 0)
  U bits = 0;
  for (int c = 0; c < D; ++c) {
    U u;
    std::memcpy(&u, s + c, sizeof(S));
    bits |= u;
  }
  if (bits != 0)
    for (int c = 0; c < D; ++c) s[c] = S(0);
}

// clear<S, D>(s) unless `keep`, with one branch that is almost never taken (a spring that is
// not zero where its pair is out of reach: a contact that has just opened far), so that it
// costs no misprediction where `keep` varies from slot to slot
template <typename S, int D>
inline void clear_unless(S* s, bool keep) {
  using U = std::conditional_t<sizeof(S) == 8, uint64_t, uint32_t>;
  U bits = 0;
  for (int c = 0; c < D; ++c) {
    U u;
    std::memcpy(&u, s + c, sizeof(S));
    bits |= u;
  }
  // the test on the bits masked by `keep` (GCC makes two branches of `(bits != 0) & !keep`,
  // the first as unpredictable as whether the slot touches)
  const U mask = U(0) - U(!keep);
  if ((bits & mask) != 0)
    for (int c = 0; c < D; ++c) s[c] = S(0);
}

// conductance of a conducting pair at centre distance L (see the header), W/K
inline double conductance(int law, double h, double ri, double rj, double L) {
  if (law == 0) {
    const double rm = ri < rj ? ri : rj;
    return h * kPi * rm * rm;
  }
  const double area = -0.25 * kPi * (L - ri - rj) * (L + ri - rj) * (L - ri + rj) *
                      (L + ri + rj) / (L * L);
  return area > 0 ? h * std::sqrt(area) : 0.0;
}

// Friction heat, per contact (see the header): the spring energy before the step,
// k_n delta_0^2 / 2 (while delta_0 > 0) + k_t |xi_old|^2 / 2, as ContactForces' _pair_work and
// _spring_energy_and_rates compute it; xi2 = |xi_old|^2
template <typename S>
inline S energy_before(const Law<S>& c, S ov0, S xi2) {
  return (ov0 > S(0) ? S(0.5)*c.kn*(ov0*ov0) : S(0)) + S(0.5)*c.kt*xi2;
}

// a contact that does not touch now: D = U_old; the tangential spring's energy is booked as
// sliding (contact_law: the release of a contact that opens)
template <typename S>
inline void opened(const Law<S>& c, S ov0, S xi2, S* dU, double* R) {
  *dU = -energy_before<S>(c, ov0, xi2);
  R[1] += double(S(0.5)*c.kt*xi2);
}

// the nearest periodic image of a difference d of last coordinates (period L; positions are
// kept in [0, L), so |d| < L): the same as d - L rint(d / L), without a libm call per pair
template <typename S>
inline S nearest_image(S d, S L) {
  return d > S(0.5)*L ? d - L : (d < S(-0.5)*L ? d + L : d);
}

// the overlap of a pair before the step, at the positions before the drift x - dt v (the JAX
// kernel's `prev`), with the nearest periodic image of the last axis
template <typename S, int D>
inline S overlap_before(const S* xi, const S* xj, const S* vi, const S* vj, S rs, S dt, S L) {
  S d0[D];
  for (int c = 0; c < D; ++c) d0[c] = (xj[c] - dt*vj[c]) - (xi[c] - dt*vi[c]);
  if constexpr (D == 3)
    if (L > S(0)) d0[2] = nearest_image(d0[2], L);
  return rs - std::sqrt(dot<S, D>(d0, d0));
}

// The contact law of up to Tile::N pair slots within reach, one array per quantity (structure
// of arrays): Loop::tile gathers the slots' data into it, pair_law_tile computes the law of all
// of them in one loop without branches, which the compiler runs in vector instructions (several
// contacts per instruction), and Loop::tile puts the results out slot by slot. 49 arrays of
// 64 (3D, float64; 61 with friction heat): 25 kB (31 kB), about the size of a core's
// first-level cache.
template <typename S, int D>
struct Tile {
  static constexpr int DW = D == 3 ? 3 : 1;
  static constexpr int N = 64;
  // gathered: the slot's geometry (d from i to j, |d|^2), radii, masses, moments of inertia
  // (rolling only), velocities, spins, the old spring and the law of the material pair
  alignas(64) S d[D][N], dist2[N], ri[N], rj[N], mi[N], mj[N], ii[N], ij[N];
  alignas(64) S vi[D][N], vj[D][N], wi[DW][N], wj[DW][N], so[D][N];
  alignas(64) S kn[N], kt[N], gn[N], gt[N], mu[N], mur[N];
  // computed (meaningful where ov > 0): centre distance, overlap, normal force, the force on j,
  // the new spring, the torques on i and j of the force and the rolling torque on j
  alignas(64) S dist[N], ov[N], fn[N], f[D][N], s[D][N], ti[DW][N], tj[DW][N], M[DW][N];
  // friction heat only: gathered, the overlap before the step and |old spring|^2; computed, the
  // levers, the law's losses (dashpots, Coulomb limit), the rolling loss and U_new - U_old
  alignas(64) S ov0[N], xi2[N], ai[D][N], aj[D][N], loss[2][N], lroll[N], du[N];
};

// x86-64: the loop of pair_law_tile compiled for AVX-512, AVX2 and the baseline (SSE2), the one
// the processor runs chosen when the library is loaded. The results do not depend on which:
// the same operations on every lane, no contraction into fused multiply-adds (-ffp-contract=off
// in cpu_kernel.FLAGS), sqrt and division exactly rounded in every instruction set. GCC with
// glibc only: the choice at load time needs the loader's indirect functions (ifunc), which other
// C libraries (musl) lack; elsewhere the baseline version alone.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__GLIBC__)
#define DRUMHEAT_VECTOR_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
// the pass that packs the particles' records (pack_range) compiled with and without the
// processor's fused multiply-add: its explicit std::fma (the drift's and the drum shell's, as
// XLA rounds them) is then one instruction instead of a call into the C library (the same
// number either way)
#define DRUMHEAT_FMA_CLONES __attribute__((target_clones("fma", "default")))
#else
#define DRUMHEAT_VECTOR_CLONES
#define DRUMHEAT_FMA_CLONES
#endif

// the law of the tile's slots [0, cnt) (ROT: the torques, ROLL: rolling resistance, FH: what
// friction heat needs)
template <typename S, int D, bool ROT, bool ROLL, bool FH>
DRUMHEAT_VECTOR_CLONES void pair_law_tile(Tile<S, D>& t, int cnt, S dt) {
  constexpr int DW = Tile<S, D>::DW;
  for (int q = 0; q < cnt; ++q) {
    const S dist = std::sqrt(t.dist2[q]);
    const S ri = t.ri[q], rj = t.rj[q];
    const S ov = (ri + rj) - dist;
    const S inv0 = S(1) / dist;
    const S inv = dist > S(0) ? inv0 : S(0);
    const S li = ri - S(0.5)*ov, lj = -(rj - S(0.5)*ov);
    S nr[D], ai[D], aj[D], ci[D], cj[D], vr[D], so[D], s[D], f[D], wi[DW], wj[DW];
    for (int c = 0; c < D; ++c) {
      nr[c] = t.d[c][q]*inv; ai[c] = li*nr[c]; aj[c] = lj*nr[c]; so[c] = t.so[c][q];
    }
    for (int c = 0; c < DW; ++c) { wi[c] = t.wi[c][q]; wj[c] = t.wj[c][q]; }
    spin_cross<S, D>(wi, ai, ci);
    spin_cross<S, D>(wj, aj, cj);
    for (int c = 0; c < D; ++c) vr[c] = (t.vj[c][q] + cj[c]) - (t.vi[c][q] + ci[c]);
    const S mi = t.mi[q], mj = t.mj[q];
    const Law<S> law{t.kn[q], t.kt[q], t.gn[q], t.gt[q], t.mu[q], t.mur[q]};
    S loss[2];
    const S fn = contact<S, D>(law, dt, nr, ov, vr, mi*mj/(mi + mj), so, s, f,
                               FH ? loss : nullptr);
    t.dist[q] = dist; t.ov[q] = ov; t.fn[q] = fn;
    for (int c = 0; c < D; ++c) { t.f[c][q] = f[c]; t.s[c][q] = s[c]; }
    if constexpr (FH) {
      for (int c = 0; c < D; ++c) { t.ai[c][q] = ai[c]; t.aj[c][q] = aj[c]; }
      t.loss[0][q] = loss[0]; t.loss[1][q] = loss[1];
      t.du[q] = (S(0.5)*law.kn*(ov*ov) + S(0.5)*law.kt*dot<S, D>(s, s))
                - energy_before<S>(law, t.ov0[q], t.xi2[q]);
    }
    if constexpr (ROT) {
      S ti[DW], tj[DW];
      torque<S, D>(ai, f, S(-1), ti);  // a_i x (-f)
      torque<S, D>(aj, f, S(1), tj);   // a_j x f
      for (int c = 0; c < DW; ++c) { t.ti[c][q] = ti[c]; t.tj[c][q] = tj[c]; }
    }
    if constexpr (ROLL) {
      S wr[DW], M[DW];
      for (int c = 0; c < DW; ++c) wr[c] = wj[c] - wi[c];
      const S ii = t.ii[q], ij = t.ij[q], ieff = ii*ij/(ii + ij);
      rolling<S, DW>(wr, fn, ri*rj/(ri + rj), law.mur, ieff, dt, M);
      for (int c = 0; c < DW; ++c) t.M[c][q] = M[c];
      if constexpr (FH) t.lroll[q] = rolling_loss<S, DW>(M, wr, ieff, dt);
    }
  }
}

// values per particle of the packed positions and radii (x_0 .. x_{D-1}, r, padding) and of
// the packed motion (v_0 .. v_{D-1}, the spin's DW components, mass, moment of inertia,
// padding), pack_particles
constexpr int XR = 4, VW = 8;

// What the scan finds for a block of pair slots (Loop::pairs): for each, d from i to j (the
// nearest periodic image of the last axis), |d|^2, whether the pair lies within reach and
// whether it conducts (output 11); and the radii and whether the slot holds a pair, which
// gather_partners reads for the tests.
template <typename S, int D>
struct Block {
  static constexpr int N = 256;
  alignas(64) S d[D][N], dist2[N], ri[N], rj[N];
  alignas(64) unsigned char within[N], cd[N], real[N];
};

// The partners' data of the pair slots [0, cnt) of (pi, pj) gathered into the Block for
// within_reach: d from i to j (before the periodic image is taken), the radii and whether the
// slot holds a pair (i < n; a padding slot reads particle 0). xr: each particle's position and
// radius in one record of XR values (pack_particles), so that a partner's come from one cache
// line. Compiled without target_clones, for the baseline instruction set, which has no vector
// gathers.
template <typename S, int D, bool RANKED>
void gather_partners(const int32_t* __restrict pi, const int32_t* __restrict pj, int cnt,
                     const S* __restrict xr, const int32_t* __restrict rk, int32_t n,
                     Block<S, D>& b) {
  for (int k = 0; k < cnt; ++k) {
    const int32_t i0 = pi[k], j0 = pj[k];
    const bool real = i0 < n;
    const int32_t iu = real ? i0 : 0, ju = real ? j0 : 0;  // padding reads particle 0
    const int32_t i = RANKED ? rk[iu] : iu, j = RANKED ? rk[ju] : ju;  // where their data lie
    const S* __restrict a = xr + XR*i;
    const S* __restrict c = xr + XR*j;
    for (int q = 0; q < D; ++q) b.d[q][k] = c[q] - a[q];
    b.ri[k] = a[D];
    b.rj[k] = c[D];
    b.real[k] = real;
  }
}

// The Block of the pair slots k of (pi, pj) [0, cnt): d from i to j (the nearest periodic image
// of the last axis with PERIODIC; with RANKED the partners' data read at their ranks rk) and
// |d|^2, whether the pair lies within reach, i.e. its centre distance |d| is at most the bound
// r_i + r_j + gap beyond which it can neither touch nor conduct heat in this loop (gap = gapf
// d_min, gapf the conduction gap tolerance of the heat flow, 0 without one): the exact tests
// of Loop::tile (on the overlap, as the JAX kernel decides) cannot pass beyond it (the factor
// 1.0001 on the squares keeps round-off on the safe side); and output 11, whether the pair
// conducts: it overlaps, or with cgap > 0 its overlap is at least -cgap d_min (the test of
// forces.ContactForces.pair_gap_mask, on the overlap computed as Loop::tile computes it). That
// test needs only the distance and the radii, so it is made here for every slot, and a pair
// within the gap cgap that does not touch is not gathered into a tile (in the built-in drum
// about as many pairs lie within the gap as touch). 0 for a padding slot (i >= n). The
// partners' data are read for every listed pair here, and most lie out of reach in a turning
// bed: they are read first (gather_partners), one load after another, and the tests then run
// over the Block in one loop without branches, in vector instructions (the vector gathers of
// AVX2 cost more per element than as many plain loads).
template <typename S, int D, bool PERIODIC, bool RANKED>
DRUMHEAT_VECTOR_CLONES void within_reach(const int32_t* __restrict pi, const int32_t* __restrict pj,
                                         int cnt, const S* __restrict xr,
                                         const int32_t* __restrict rk, int32_t n, S L, S gapf,
                                         S cgap, Block<S, D>& b) {
  gather_partners<S, D, RANKED>(pi, pj, cnt, xr, rk, n, b);
  for (int k = 0; k < cnt; ++k) {
    S d[D];
    for (int c = 0; c < D; ++c) d[c] = b.d[c][k];
    if constexpr (PERIODIC) d[2] = nearest_image(d[2], L);
    const S dist2 = dot<S, D>(d, d);
    const S ri = b.ri[k], rj = b.rj[k];
    const S rmin = ri < rj ? ri : rj;
    const S gap = gapf*(S(2)*rmin), cg = cgap*(S(2)*rmin);
    const S re = (ri + rj) + gap;
    const bool real = b.real[k];
    if constexpr (PERIODIC) b.d[2][k] = d[2];
    b.dist2[k] = dist2;
    b.within[k] = real & !(dist2 > re*re*S(1.0001));
    const S ov = (ri + rj) - std::sqrt(dist2);
    b.cd[k] = real & (cgap > S(0) ? ov >= -cg : ov > S(0));
  }
}

// Work buffers (the records, the layout, the per-chunk accumulators) that live across calls
// (no allocation and page faults every step). A call takes the smallest free buffer that holds
// what it asks for (else the largest, grown), so that each of a call's buffers gets the one of
// its own size back in the next call (taking the last one given back, the buffers changed roles
// between calls and each grew to the largest size asked for).
using Buffer = std::vector<double>;
std::mutex g_buf_mu;
std::vector<std::unique_ptr<Buffer>> g_bufs;

std::unique_ptr<Buffer> take_buffer(size_t size) {
  std::unique_ptr<Buffer> b;
  {
    std::lock_guard<std::mutex> lock(g_buf_mu);
    // the smallest buffer that holds `size`, else the largest
    using Held = std::unique_ptr<Buffer>;
    const auto before = [size](const Held& a, const Held& c) {
      const bool fa = a->size() >= size, fc = c->size() >= size;
      if (fa != fc) return fa;
      return fa ? a->size() < c->size() : a->size() > c->size();
    };
    const auto it = std::min_element(g_bufs.begin(), g_bufs.end(), before);
    if (it != g_bufs.end()) { b = std::move(*it); g_bufs.erase(it); }
  }
  if (!b) b = std::make_unique<Buffer>();
  if (b->size() < size) b->resize(size);
  return b;
}

void give_buffer(std::unique_ptr<Buffer> b) {
  std::lock_guard<std::mutex> lock(g_buf_mu);
  g_bufs.push_back(std::move(b));
}

// The chunks of a call (see the header): chunk c takes the pair slots [kb[c], kb[c + 1]), the
// padding slots [pb[c], pb[c + 1]) (an equal share of the slots past the listed pairs of a
// list sorted by i: they only need their outputs zeroed, which would otherwise fall on the
// last chunk alone) and the wall slots of the particles [n c / nc, n (c + 1) / nc)
struct Chunks {
  int64_t n, nw, nc;
  std::vector<int64_t> kb, pb;
  int64_t s0(int64_t c) const { return n * c / nc * nw; }  // the first wall slot of chunk c
  int64_t s1(int64_t c) const { return n * (c + 1) / nc * nw; }  // past its last
};

// the chunks for the pairs P (2, M) of n particles with nw walls: C from the listed pairs (the
// slots before the padding i = n), the pair slots cut where the groups of the particles of the
// listed pairs listed c / C begin. rk: null
// (the ranges are of particle indices, for a list sorted by i) or each particle's rank in the
// cell order (ranges of ranks, for a list grouped in that order, Loop::RK). The cuts are found
// by binary searches, which assume the list so sorted, as the neighbour builds leave it; any
// other list is still computed right: the cuts are kept in order (every slot in one chunk),
// and unless every slot past the first padding slot found is padding, all slots count as
// listed (the scan tells padding from pairs slot by slot); its chunks are only uneven.
Chunks chunks(ffi::ThreadPool& pool, const int32_t* P, int64_t n, int64_t m, int64_t nw,
              const int32_t* rk) {
  // the slot's particle range key: its first particle's index (or rank), n for padding
  auto key = [&](int64_t k) -> int64_t {
    const int32_t i = P[k];
    return i < n ? (rk ? rk[i] : i) : n;
  };
  auto first_at_least = [&](int64_t v) {  // the first slot whose key is at least v
    int64_t lo = 0, hi = m;
    while (lo < hi) {
      const int64_t mid = lo + (hi - lo) / 2;
      if (key(mid) < v) lo = mid + 1; else hi = mid;
    }
    return lo;
  };
  int64_t listed = first_at_least(n);
  int tail = 0;  // whether a pair lies past it (one pass without an early exit: vectorised)
  for (int64_t k = listed; k < m; ++k) tail |= P[k] < n;
  if (tail) listed = m;
  const int64_t nc = team_size(pool, listed / MIN_CHUNK, n);
  Chunks ch{n, nw, nc, std::vector<int64_t>(nc + 1, listed), std::vector<int64_t>(nc + 1, m)};
  for (int64_t c = 0; c < nc; ++c) {
    // chunk c from the first particle (index or rank) of the listed pair listed c / C on: as
    // many listed pairs in each chunk as whole particles' groups allow
    const int64_t cut = c == 0 || listed == 0 ? n * c / nc : key(listed * c / nc);
    ch.kb[c] = c == 0 ? 0 : std::min(std::max(first_at_least(cut), ch.kb[c - 1]), listed);
    ch.pb[c] = listed + (m - listed) * c / nc;
  }
  return ch;
}

// the buffers of one call, untyped (their dtype is checked in ContactsImpl)
struct Call {
  const void *x, *v, *w, *r, *ms, *in, *sp, *wd, *wn, *wv, *ws, *tpp, *tpw, *wom, *wd0;
  // the strides of r, ms and in: 1, or 0 where one value stands for every particle
  int64_t r_step = 1, ms_step = 1, in_step = 1;
  const int32_t *pt, *P, *order;  // order: null, or the particles in the order of their cells
  const double* temp;
  // body: null, or the body force added to each particle's force, one row per particle
  // (body_step D) or one for all (body_step 0)
  const void* body = nullptr;
  int64_t body_step = 0;
  // ahead: null, or the constants of the coming step's skin test (input 20) and ref the
  // reference positions (input 21); AH its output
  const void *ahead = nullptr, *ref = nullptr;
  void* AH = nullptr;
  // shell: null, or the drum shell's R and omega (input 22: wall 0's geometry computed here)
  const void* shell = nullptr;
  bool* CW = nullptr;  // null, or whether each wall slot conducts (output 16)
  // drift: null, or the constants of the step's kicks and drift (input 23) with the forces and
  // torques of the step before (df, dtq, inputs 24-25); DX, DV, DWo: x', v', w' (outputs 17-19)
  const void *drift = nullptr, *df = nullptr, *dtq = nullptr;
  void *DX = nullptr, *DV = nullptr, *DWo = nullptr;
  // steps: null, or the run of steps (input 26: K and half the skin squared), with PC, WC
  // each pair slot's and wall slot's count of the steps it conducts (outputs 20-21) and DONE
  // the steps made (output 22)
  const void* steps = nullptr;
  int32_t *PC = nullptr, *WC = nullptr, *DONE = nullptr;
  // a step of a run after its first: the per-slot outputs are the step before's buffers, in
  // which the padding slots' are written already (run_steps)
  bool later = false;
  void *F, *T, *S, *OV, *DI, *FN, *WS, *WO, *WF, *MX, *PW, *WW;
  double *Q, *R;
  bool* CD;
  int64_t n, m, nw, nt;
  double dt, L, h, tol, cgap, wgap;
  int law;
  bool rot, fh;
};

// The typed buffers and constants of one call of the loop (run): pairs() and walls() compute the
// pair slots [k0, k1) and the wall slots [s0, s1) of a chunk into its accumulators F (N, D),
// T (N, DW), Q (N) and R (3, the loss rates of friction heat) and return the largest overlap
// ratio seen. Per-slot outputs are disjoint between chunks.
template <typename S, int D>
struct Loop {
  static constexpr int DW = D == 3 ? 3 : 1;  // spin and torque components
  static constexpr int KP = 3*D + DW + 1, KW = 2*D + DW + 1;  // friction heat rows (header)
  const Call& a;
  int64_t n, m, nw, nt;
  const S *x, *v, *w, *r, *ms, *in, *sp, *WD, *WN, *WV, *WS, *WOM, *WD0;
  const int32_t *pt, *P;
  // RK: null, or where each particle's data lie in XRp, VWp and TK (its rank in the cell
  // order: run() lays the particles' data out in that order, and the forces, torques and heat
  // are summed there); pt and every per-slot array stay in the particles' own numbering
  const int32_t* RK = nullptr;
  // the particles' data as the loop reads them (pack_particles): the positions and radii, XR
  // values per particle, and the velocities, spins, masses and moments of inertia, VW values
  // per particle (x, v, w, r, ms, in above are the inputs in the particles' own numbering)
  const S *XRp = nullptr, *VWp = nullptr;
  // with the drum shell (SH): each particle's distance from the z axis, where its data lie
  // (pack_particles)
  const S* RHO = nullptr;
  S *Sn, *WSo, *OV, *DI, *FN, *WO, *WF, *PW, *WW;  // OV, DI, FN null: not wanted
  bool *CD, *CW;
  int32_t *PC, *WC;  // null, or the slots' counts of the steps they conduct (a run of steps)
  const double* TK;
  bool heat_on, gap_on, rot, fh, one_type, roll_pp = false, roll_pw = false;
  S dt, L, tol, cgap, wgap;
  // the drum shell (input 22): wall 0's geometry computed here, the given geometry (inputs
  // 9-11) of the walls 1 .. nw - 1 (ng of them per particle); else ng = nw
  const S* SH = nullptr;
  int64_t ng;
  std::vector<Law<S>> pp, pw;

  explicit Loop(const Call& c) : a(c), n(c.n), m(c.m), nw(c.nw), nt(c.nt) {
    x = static_cast<const S*>(a.x); v = static_cast<const S*>(a.v);
    w = static_cast<const S*>(a.w); r = static_cast<const S*>(a.r);
    ms = static_cast<const S*>(a.ms); in = static_cast<const S*>(a.in);
    sp = static_cast<const S*>(a.sp); WD = static_cast<const S*>(a.wd);
    WN = static_cast<const S*>(a.wn); WV = static_cast<const S*>(a.wv);
    WS = static_cast<const S*>(a.ws); WOM = static_cast<const S*>(a.wom);
    WD0 = static_cast<const S*>(a.wd0);
    pt = a.pt; P = a.P;
    Sn = static_cast<S*>(a.S); WSo = static_cast<S*>(a.WS);
    OV = static_cast<S*>(a.OV); DI = static_cast<S*>(a.DI); FN = static_cast<S*>(a.FN);
    WO = static_cast<S*>(a.WO); WF = static_cast<S*>(a.WF);
    PW = static_cast<S*>(a.PW); WW = static_cast<S*>(a.WW);
    CD = a.CD; CW = a.CW; PC = a.PC; WC = a.WC;
    SH = static_cast<const S*>(a.shell);
    ng = SH ? nw - 1 : nw;
    TK = a.temp;
    heat_on = a.law >= 0; gap_on = heat_on && a.tol > 0; rot = a.rot; fh = a.fh;
    dt = S(a.dt); L = S(a.L); tol = S(a.tol); cgap = S(a.cgap); wgap = S(a.wgap);
    pp = laws<S>(static_cast<const S*>(a.tpp), nt, nt);
    pw = laws<S>(static_cast<const S*>(a.tpw), nt, nw);
    one_type = nt == 1;
    for (const auto& c : pp) roll_pp = roll_pp || c.mur > S(0);
    for (const auto& c : pw) roll_pw = roll_pw || c.mur > S(0);
    roll_pp = roll_pp && rot;
    roll_pw = roll_pw && rot;
  }

  // where the data of particle i lie (its rank in the cell order, or i)
  int32_t at(int32_t i) const { return RK ? RK[i] : i; }

  // the law of the listed pair (i, j)
  const Law<S>& pair_law(int32_t i, int32_t j) const {
    return one_type ? pp[0] : pp[pt[i]*nt + pt[j]];
  }

  // friction heat: the springs' energy before the step, |xi_old|^2 and the overlap before the
  // step's drift (read before the spring is written)
  S spring2(int64_t k) const { return fh ? dot<S, D>(sp + D*k, sp + D*k) : S(0); }
  S overlap0(int32_t i, int32_t j) const {  // i, j: where their data lie (at)
    const S *a = XRp + XR*i, *b = XRp + XR*j;
    return fh ? overlap_before<S, D>(a, b, VWp + VW*i, VWp + VW*j, a[D] + b[D], dt, L) : S(0);
  }

  // padding slots [p0, p1) (past the listed pairs): the outputs of a pair that does not touch
  void padding(int64_t p0, int64_t p1) const {
    for (int64_t k = p0; k < p1; ++k) {
      if (fh) for (int c = 0; c < KP; ++c) PW[KP*k + c] = S(0);
      if (OV) { OV[k] = S(0); DI[k] = S(0); FN[k] = S(0); }
      CD[k] = false;
      clear<S, D>(Sn + D*k);
    }
  }

  // The pair slots [k0, k1) in blocks of BLOCK slots, two passes per block. The scan tells
  // which slots lie within reach and which conduct (within_reach, in vector instructions),
  // writes every slot's outputs as for a pair that does not touch (zeros, the spring cleared,
  // with friction heat the opened contact's row) and collects the slots within reach in a
  // short list (a slot's index written and the count advanced by the flag: no branch on the
  // geometry, so the processor does not mispredict on the many listed pairs out of reach);
  // `tile` then computes the list, Tile::N slots at a time, while its slots are still in the
  // cache.
  static constexpr int64_t BLOCK = Block<S, D>::N;

  S pairs(int64_t k0, int64_t k1, S* F, S* T, double* Q, double* R) const {
    S max_ov = S(0);
    int64_t near[BLOCK];
    std::unique_ptr<Tile<S, D>> tl(new Tile<S, D>);  // off the thread's stack
    std::unique_ptr<Block<S, D>> bl(new Block<S, D>);
    if (one_type) fill_law(*tl, pp[0]);
    const unsigned char* within = bl->within;
    for (int64_t b0 = k0; b0 < k1; b0 += BLOCK) {
      const int64_t b1 = b0 + BLOCK < k1 ? b0 + BLOCK : k1;
      const int nb = static_cast<int>(b1 - b0);
      const int32_t n32 = static_cast<int32_t>(n);
      const S gapf = gap_on ? tol : S(0);
      if (D == 3 && L > S(0)) {
        if (RK) within_reach<S, D, true, true>(P + b0, P + m + b0, nb, XRp, RK, n32, L, gapf,
                                               cgap, *bl);
        else within_reach<S, D, true, false>(P + b0, P + m + b0, nb, XRp, RK, n32, L, gapf,
                                             cgap, *bl);
      } else {
        if (RK) within_reach<S, D, false, true>(P + b0, P + m + b0, nb, XRp, RK, n32, L, gapf,
                                                cgap, *bl);
        else within_reach<S, D, false, false>(P + b0, P + m + b0, nb, XRp, RK, n32, L, gapf,
                                              cgap, *bl);
      }
      // zero where nothing touches (written here, while the lines are at hand: a sweep over
      // the whole output first would pass them through the cache twice where they do not fit),
      // and which pairs conduct, for every slot
      if (OV) for (int64_t k = b0; k < b1; ++k) { OV[k] = S(0); DI[k] = S(0); FN[k] = S(0); }
      for (int64_t k = b0; k < b1; ++k) CD[k] = bl->cd[k - b0];
      if (PC) for (int64_t k = b0; k < b1; ++k) PC[k] += bl->cd[k - b0];
      if (fh) for (int64_t k = KP*b0; k < KP*b1; ++k) PW[k] = S(0);
      if (fh)  // the opened contacts' rows, from the old springs before they are cleared
        for (int64_t k = b0; k < b1; ++k)
          if (!within[k - b0] && P[k] < n) {
            const int32_t i = P[k], j = P[m + k];
            opened<S>(pair_law(i, j), overlap0(at(i), at(j)), spring2(k), PW + KP*k + KP - 1,
                      R);
          }
      // (a loop of its own: in this one a branch on `within`, which varies from slot to slot,
      // would be mispredicted at every other slot)
      int64_t cnt = 0;
      for (int q = 0; q < nb; ++q) {
        const int64_t k = b0 + q;
        near[cnt] = k;
        cnt += within[q];
        clear_unless<S, D>(Sn + D*k, within[q]);  // a padding slot is never within reach
      }
      for (int64_t q = 0; q < cnt; q += Tile<S, D>::N) {
        const int c = static_cast<int>(cnt - q < Tile<S, D>::N ? cnt - q : Tile<S, D>::N);
        const S ratio_ov = tile(*tl, *bl, b0, near + q, c, F, T, Q, R);
        if (ratio_ov > max_ov) max_ov = ratio_ov;
      }
    }
    return max_ov;
  }

  // The slots near[0 .. cnt) within reach (cnt <= Tile::N; the scan has written their outputs
  // as for an open contact): their data gathered into the tile, the law in vector instructions
  // (pair_law_tile), the results put out slot by slot in the list's order (every sum takes its
  // terms in that order, whichever instruction set ran the law). Returns the largest
  // overlap / smaller radius (0 where nothing touches).
  // bl: the scan's Block of the slots from b0 on.
  S tile(Tile<S, D>& t, const Block<S, D>& bl, int64_t b0, const int64_t* near, int cnt, S* F,
         S* T, double* Q, double* R) const {
    for (int q = 0; q < cnt; ++q) {
      const int64_t k = near[q], b = k - b0;
      const int32_t iu = P[k], ju = P[m + k], i = at(iu), j = at(ju);
      const Law<S>& law = pair_law(iu, ju);
      const S *ui = VWp + VW*i, *uj = VWp + VW*j;  // the partners' motion records
      for (int c = 0; c < D; ++c) {
        t.d[c][q] = bl.d[c][b]; t.vi[c][q] = ui[c]; t.vj[c][q] = uj[c];
        t.so[c][q] = sp[D*k + c];
      }
      for (int c = 0; c < DW; ++c) { t.wi[c][q] = ui[D + c]; t.wj[c][q] = uj[D + c]; }
      t.dist2[q] = bl.dist2[b]; t.ri[q] = XRp[XR*i + D]; t.rj[q] = XRp[XR*j + D];
      t.mi[q] = ui[D + DW]; t.mj[q] = uj[D + DW];
      if (roll_pp) { t.ii[q] = ui[D + DW + 1]; t.ij[q] = uj[D + DW + 1]; }
      if (!one_type) set_law(t, q, law);  // (one material: the tile holds its law already)
      if (fh) {  // before the spring is written
        t.ov0[q] = overlap0(i, j);
        t.xi2[q] = spring2(k);
      }
    }
    if (fh) law_tile<true>(t, cnt);
    else law_tile<false>(t, cnt);
    S max_ov = S(0);
    for (int q = 0; q < cnt; ++q) {
      const int64_t k = near[q];
      const int32_t i = at(P[k]), j = at(P[m + k]);  // where their data and sums lie
      const S ri = t.ri[q], rj = t.rj[q], rmin = ri < rj ? ri : rj;
      const S ov = t.ov[q], dist = t.dist[q];
      S* s = Sn + D*k;
      S* hw = fh ? PW + KP*k : nullptr;  // friction heat row (header)
      if (!(ov > S(0))) {
        if (fh) opened<S>(Law<S>{t.kn[q], t.kt[q]}, t.ov0[q], t.xi2[q], hw + KP - 1, R);
        clear<S, D>(s);
        if (gap_on && ov >= -(tol*(S(2)*rmin))) {
          const double qh = conductance(a.law, a.h, ri, rj, dist) * (TK[j] - TK[i]);
          Q[i] += qh; Q[j] -= qh;
        }
        continue;
      }
      if (OV) FN[k] = t.fn[q];
      if (fh) { R[0] += double(t.loss[0][q]); R[1] += double(t.loss[1][q]); }
      for (int c = 0; c < D; ++c) { F[D*j + c] += t.f[c][q]; F[D*i + c] -= t.f[c][q]; }
      if (rot) {
        for (int c = 0; c < DW; ++c) T[DW*i + c] += t.ti[c][q];
        for (int c = 0; c < DW; ++c) T[DW*j + c] += t.tj[c][q];
        if (roll_pp) {
          for (int c = 0; c < DW; ++c) { T[DW*j + c] += t.M[c][q]; T[DW*i + c] -= t.M[c][q]; }
          if (fh) R[2] += double(t.lroll[q]);
        }
      }
      for (int c = 0; c < D; ++c) s[c] = t.s[c][q];
      if (fh) {
        for (int c = 0; c < D; ++c) {
          hw[c] = t.f[c][q]; hw[D + c] = t.ai[c][q]; hw[2*D + c] = t.aj[c][q];
        }
        for (int c = 0; c < DW; ++c) hw[3*D + c] = roll_pp ? t.M[c][q] : S(0);
        hw[KP - 1] = t.du[q];
      }
      if (OV) { OV[k] = ov; DI[k] = dist; }
      if (heat_on) {
        const double qh = conductance(a.law, a.h, ri, rj, dist) * (TK[j] - TK[i]);
        Q[i] += qh; Q[j] -= qh;
      }
      const S r_ov = ov / rmin;
      if (r_ov > max_ov) max_ov = r_ov;
    }
    return max_ov;
  }

  // the law of the material pair c in the tile's slot q, and in all of them
  static void set_law(Tile<S, D>& t, int q, const Law<S>& c) {
    t.kn[q] = c.kn; t.kt[q] = c.kt; t.gn[q] = c.gn; t.gt[q] = c.gt; t.mu[q] = c.mu;
    t.mur[q] = c.mur;
  }
  static void fill_law(Tile<S, D>& t, const Law<S>& c) {
    for (int q = 0; q < Tile<S, D>::N; ++q) set_law(t, q, c);
  }

  // pair_law_tile for this call's torques and rolling resistance
  template <bool FH>
  void law_tile(Tile<S, D>& t, int cnt) const {
    if (roll_pp) pair_law_tile<S, D, true, true, FH>(t, cnt, dt);
    else if (rot) pair_law_tile<S, D, true, false, FH>(t, cnt, dt);
    else pair_law_tile<S, D, false, false, FH>(t, cnt, dt);
  }

  // the drum shell (input 22) at the particle at xp, rho from the z axis: the unit normal nr
  // towards it, -e_rho, and the wall's velocity omega e_z x (R e_rho) (DrumShell.evaluate:
  // e_rho = (1, 0) on the axis)
  void shell_at(const S* xp, S rho, S* nr, S* wv) const {
    const bool off = rho > S(1e-30);
    const S inv = S(1) / (off ? rho : S(1));  // (header: XLA's roundings)
    const S ex = off ? xp[0]*inv : S(1), ey = off ? xp[1]*inv : S(0);
    const S R = SH[0], om = SH[1];
    nr[0] = -ex; nr[1] = -ey;
    wv[0] = (-om)*(R*ey); wv[1] = om*(R*ex);
    if constexpr (D == 3) { nr[2] = S(0); wv[2] = S(0); }
  }

  // walls: partner A is the wall (spin omega_wall about z, infinite mass), B the particle
  S walls(int64_t s0, int64_t s1, S* F, S* T, double* R) const {
    S max_ov = S(0);
  for (int64_t q = s0; q < s1; ++q) {
    const int64_t pu = q / nw, wl = q % nw, p = at(static_cast<int32_t>(pu));  // p: its data
    S* s = WSo + D*q;
    const S* so = WS + D*q;
    S* hw = fh ? WW + KW*q : nullptr;  // friction heat row (header)
    if (fh) for (int c = 0; c < KW; ++c) hw[c] = S(0);
    const S* u = VWp + VW*p;  // its velocity, spin, mass and moment of inertia
    const S rp = XRp[XR*p + D];
    const bool sh = SH && wl == 0;  // the drum shell's slot: its geometry computed here
    const int64_t g = pu*ng + wl - (SH ? 1 : 0);  // else the slot of its given geometry
    const S* xp = XRp + XR*p;
    const S rho = sh ? RHO[p] : S(0);
    const S ov = rp - (sh ? SH[0] - rho : WD[g]);
    if (CW) CW[q] = wgap > S(0) ? ov >= -(wgap*(S(2)*rp)) : ov > S(0);
    if (WC) WC[q] += CW[q];
    const Law<S>& law = pw[(one_type ? 0 : pt[pu])*nw + wl];
    const S xi2 = fh ? dot<S, D>(so, so) : S(0);
    const S ov0 = fh ? rp - WD0[q] : S(0);  // the walls before the step, from JAX
    WO[q] = S(0); WF[q] = S(0);
    if (!(ov > S(0))) {
      if (fh) opened<S>(law, ov0, xi2, hw + KW - 1, R);
      clear<S, D>(s);
      continue;
    }
    S nb[D], vb[D];  // the shell's normal and velocity at the particle
    if (sh) shell_at(xp, rho, nb, vb);
    const S* nr = sh ? nb : WN + D*g;
    const S* wv = sh ? vb : WV + D*g;
    const S l = -(rp - S(0.5)*ov);
    S al[D], cw[D], vr[D], f[D], M[DW] = {};
    for (int c = 0; c < D; ++c) al[c] = l*nr[c];
    spin_cross<S, D>(u + D, al, cw);
    for (int c = 0; c < D; ++c) vr[c] = u[c] + cw[c] - wv[c];
    S loss[2];
    const S fn = contact<S, D>(law, dt, nr, ov, vr, u[D + DW], so, s, f, fh ? loss : nullptr);
    if (fh) { R[0] += double(loss[0]); R[1] += double(loss[1]); }
    WF[q] = fn;
    for (int c = 0; c < D; ++c) F[D*p + c] += f[c];
    if (rot) {
      add_torque<S, D>(T + DW*p, al, f, S(1));
      if (roll_pw) {
        S wr[DW];
        for (int c = 0; c < DW; ++c) wr[c] = u[D + c];
        wr[DW - 1] -= WOM[wl];  // the wall spins about z
        rolling<S, DW>(wr, fn, rp, law.mur, u[D + DW + 1], dt, M);
        for (int c = 0; c < DW; ++c) T[DW*p + c] += M[c];
        if (fh) R[2] += double(rolling_loss<S, DW>(M, wr, u[D + DW + 1], dt));
      }
    }
    if (fh) {
      for (int c = 0; c < D; ++c) { hw[c] = f[c]; hw[D + c] = al[c]; }
      for (int c = 0; c < DW; ++c) hw[2*D + c] = M[c];
      hw[KW - 1] = (S(0.5)*law.kn*(ov*ov) + S(0.5)*law.kt*dot<S, D>(s, s))
                   - energy_before<S>(law, ov0, xi2);
    }
    WO[q] = ov;
    if (ov / rp > max_ov) max_ov = ov / rp;
  }
  return max_ov;
  }
};

// The layout of the cell order (Call::order) in one buffer: the ranks (N s32: where each
// particle's data lie), then the temperatures (N doubles, with conduction). ranks() fills the
// ranks, gather_temperatures() the temperatures, pack_particles() lays the particles' other
// data out in the same order; the chunks' threads take a range of ranks each.
struct Layout {
  int64_t n, nr;
  explicit Layout(int64_t n_) : n(n_), nr((4*n_ + 7)/8) {}
  int64_t doubles() const { return nr + n; }
  int32_t* rank(Buffer& b) const { return reinterpret_cast<int32_t*>(b.data()); }
  double* temp(Buffer& b) const { return b.data() + nr; }
};

// whether `order` (N) is 0 .. N-1 (the numbering will do: no layout; one pass without an early
// exit, in vector instructions)
bool identity(const int32_t* order, int64_t n) {
  int off = 0;
  for (int64_t p = 0; p < n; ++p) off |= order[p] != p;
  return off == 0;
}

// whether the cell order `order` (null: none) lays the data out: given and not 0 .. N-1
bool layout_in_use(const int32_t* order, int64_t n) {
  return order != nullptr && !identity(order, n);
}

// each particle's rank in `order` into rk (N); false if `order` is not a permutation of 0 .. N-1
bool ranks(const int32_t* order, int64_t n, int32_t* rk) {
  std::memset(rk, 0xff, sizeof(int32_t) * n);  // -1: no rank yet
  for (int64_t p = 0; p < n; ++p) {
    const int64_t u = order[p];
    if (u < 0 || u >= n || rk[u] >= 0) return false;
    rk[u] = static_cast<int32_t>(p);
  }
  return true;
}

// What the steps of one call share (run_steps: the steps of a run have the same list, order
// and temperatures): whether the cell order lays the data out (`ranked`), the layout's buffer
// (the ranks, and with conduction the temperatures in the cell order) and the chunks
struct Shared {
  bool ranked = false;
  Layout layout{0};
  std::unique_ptr<Buffer> lay;
  Chunks ch;
  const double* temp = nullptr;  // the temperatures as the loop reads them
  const int32_t* rank = nullptr;  // null, or each particle's rank in the cell order
  Shared() = default;
  Shared(const Shared&) = delete;
  Shared& operator=(const Shared&) = delete;
  ~Shared() { if (lay) give_buffer(std::move(lay)); }
};

// the layout and the chunks of the pairs P (2, M) of n particles with nw walls in the cell
// order `order` (null: none) into sh, for both passes (Contacts, ContactHeat); false if the
// order is not a permutation
bool share(ffi::ThreadPool& pool, const int32_t* P, const int32_t* order, int64_t n, int64_t m,
           int64_t nw, Shared& sh) {
  sh.ranked = layout_in_use(order, n);
  sh.layout = Layout(n);
  if (sh.ranked) {
    sh.lay = take_buffer(sh.layout.doubles());
    if (!ranks(order, n, sh.layout.rank(*sh.lay))) return false;
    sh.rank = sh.layout.rank(*sh.lay);
  }
  sh.ch = chunks(pool, P, n, m, nw, sh.rank);
  return true;
}

// the temperatures of call a as the loop reads them (sh.temp): with the cell order and
// conduction, in that order
void gather_temperatures(Team& team, const Call& a, Shared& sh) {
  sh.temp = a.temp;
  if (!sh.ranked || a.law < 0) return;
  const int64_t n = a.n, nc = team.size();
  const int32_t* od = a.order;
  double* ts = sh.layout.temp(*sh.lay);
  team.each([&](int c) {
    for (int64_t p = n*c/nc; p < n*(c + 1)/nc; ++p) ts[p] = a.temp[od[p]];
  });
  sh.temp = ts;
}

// The step's kicks and drift (inputs 23-25, see the header): step(i) writes particle i's x', v'
// and w' (outputs 17-19) from its x, v, w (inputs 0-2) and the step before's forces and torques.
template <typename S, int D>
struct Drift {
  static constexpr int DW = D == 3 ? 3 : 1;
  bool on;
  S a = S(0), c = S(0), ci = S(0), dt = S(0), L = S(0);
  const S *x, *v, *w, *F, *M;
  S *X, *V, *W;
  explicit Drift(const Call& k)
      : on(k.drift != nullptr), x(static_cast<const S*>(k.x)), v(static_cast<const S*>(k.v)),
        w(static_cast<const S*>(k.w)), F(static_cast<const S*>(k.df)),
        M(static_cast<const S*>(k.dtq)), X(static_cast<S*>(k.DX)), V(static_cast<S*>(k.DV)),
        W(static_cast<S*>(k.DWo)) {
    if (!on) return;
    const S* q = static_cast<const S*>(k.drift);
    a = q[0]; c = q[1]; ci = q[2]; dt = q[3]; L = q[4];
  }
  // one particle's x', v', w' (yx, yv, yw) from its x, v, w (xi, vi, wi) and the forces and
  // torques fi, ti (an output may be its input's memory: each value is read, then written)
  __attribute__((always_inline)) inline void advance(const S* xi, const S* vi, const S* wi,
                                                     const S* fi, const S* ti, bool rot, S* yx,
                                                     S* yv, S* yw) const {
    for (int q = 0; q < D; ++q) {
      const S f = fi[q];
      const S u = std::fma(f, c, std::fma(a*f, c, vi[q]));  // the two half-kicks
      S y = std::fma(u, dt, xi[q]);
      if (q == D - 1 && L > S(0)) y = y >= L ? y - L : (y < S(0) ? y + L : y);
      yv[q] = u;
      yx[q] = y;
    }
    for (int q = 0; q < DW; ++q) {
      const S t = ti[q], s = wi[q];
      yw[q] = rot ? std::fma(t, ci, std::fma(a*t, ci, s)) : s;
    }
  }
  __attribute__((always_inline)) inline void step(int64_t i, bool rot) const {
    advance(x + D*i, v + D*i, w + DW*i, F + D*i, M + DW*i, rot, X + D*i, V + D*i, W + DW*i);
  }
};

// the records of the particles whose data lie at [p0, p1) (pack_particles), after the step's
// kicks and drift (dr), and with the drum shell their distance from the z axis
template <typename S, int D>
DRUMHEAT_FMA_CLONES void pack_range(const Loop<S, D>& lp, const Drift<S, D>& dr,
                                    const int32_t* od, int64_t p0, int64_t p1, S* xr, S* vw,
                                    S* rho) {
  constexpr int DW = Loop<S, D>::DW;
  const S *x = lp.x, *r = lp.r, *v = lp.v, *w = lp.w, *ms = lp.ms, *in = lp.in;
  const int64_t sr = lp.a.r_step, sm = lp.a.ms_step, si = lp.a.in_step;
  for (int64_t p = p0; p < p1; ++p) {
    const int64_t i = od ? od[p] : p;  // the particle whose data lie at p
    if (dr.on) dr.step(i, lp.rot);  // x', v', w' of particle i (in place: read, then written)
    const S *xi = dr.on ? dr.X : x, *vi = dr.on ? dr.V : v, *wi = dr.on ? dr.W : w;
    S* a = xr + XR*p;
    for (int q = 0; q < D; ++q) a[q] = xi[D*i + q];
    a[D] = r[sr*i];
    for (int q = D + 1; q < XR; ++q) a[q] = S(0);
    S* u = vw + VW*p;
    for (int q = 0; q < D; ++q) u[q] = vi[D*i + q];
    for (int q = 0; q < DW; ++q) u[D + q] = wi[DW*i + q];
    u[D + DW] = ms[sm*i];
    u[D + DW + 1] = in[si*i];
    for (int q = D + DW + 2; q < VW; ++q) u[q] = S(0);
    if (rho) rho[p] = std::sqrt(std::fma(a[0], a[0], a[1]*a[1]));  // (header: the shell)
  }
}

// What the steps of one call carry from one to the next (run_steps; a call of one step has
// its own): the particles' records (pack_particles) and the chunks' accumulators (run), each
// buffer taken from the pool once and given back when the call is done. With `next` (a step
// follows, unless the skin test stops the run) a step's pass that adds the chunks' sums makes
// the coming step's kicks, drift and records for the particles it has just summed and zeroes
// the accumulators it has read: the coming step then needs no pass of its own that reads each
// particle's x, v, w, F and M in its numbering and writes x', v', w' there, nor a memset of
// the accumulators (`drifted`: its records hold x', v', w', which its own sum pass writes out,
// outputs 17-19, and its accumulators are zero). The same arithmetic (Drift::advance), in
// other passes.
template <typename S>
struct Carry {
  std::unique_ptr<Buffer> packed;
  S *xr = nullptr, *vw = nullptr, *rho = nullptr;  // the records (pack_particles)
  std::vector<std::unique_ptr<Buffer>> acc;
  std::vector<double*> accp;  // their data
  bool next = false, drifted = false;
  Carry() = default;
  Carry(const Carry&) = delete;
  Carry& operator=(const Carry&) = delete;
  ~Carry() {
    if (packed) give_buffer(std::move(packed));
    for (auto& b : acc) give_buffer(std::move(b));
  }
};

// The particles' data packed into records, in the cell order `od` (null: their own numbering),
// in one buffer of the carry: the positions and radii XR values per particle, (x_0 .. x_{D-1},
// r, 0 ...), read by the scan for both partners of every listed pair, and the velocities, spins,
// masses and moments of inertia VW values per particle, read by the tiles for the pairs within
// reach and by the walls: each partner's come from one cache line instead of from one per
// array, and the one copy lays them out in the cell order too. With the drum shell, rho holds
// each particle's distance from its axis after them. The carry's xr, vw and rho point at them.
template <typename S, int D>
void pack_particles(Team& team, const Loop<S, D>& lp, const int32_t* od, Carry<S>& cy) {
  constexpr int DW = Loop<S, D>::DW;
  static_assert(D + 1 <= XR && D + DW + 2 <= VW, "a record holds the particle's data");
  const int64_t n = lp.n;
  const int64_t k = lp.SH ? XR + VW + 1 : XR + VW;  // values per particle
  if (!cy.packed) cy.packed = take_buffer((static_cast<int64_t>(sizeof(S))*k*n + 7)/8);
  cy.xr = reinterpret_cast<S*>(cy.packed->data());
  cy.vw = cy.xr + XR*n;
  cy.rho = lp.SH ? cy.vw + VW*n : nullptr;
  const Drift<S, D> dr(lp.a);
  const int64_t nc = team.size();
  team.each([&](int c) {
    pack_range<S, D>(lp, dr, od, n*c/nc, n*(c + 1)/nc, cy.xr, cy.vw, cy.rho);
  });
}

// The coming step's skin test (see the header): moved(i, f) is particle i's squared
// displacement from its reference position after the coming step's drift, f its force (D).
template <typename S, int D>
struct Ahead {
  bool on;
  S c = S(0), dt = S(0), L = S(0), inv_L = S(0), lo[D] = {};
  const S *x, *v, *ref;
  explicit Ahead(const Call& a)
      : on(a.ahead != nullptr),
        x(static_cast<const S*>(a.drift ? a.DX : a.x)),  // this call's positions and velocities
        v(static_cast<const S*>(a.drift ? a.DV : a.v)),
        ref(static_cast<const S*>(a.ref)) {
    if (!on) return;
    const S* k = static_cast<const S*>(a.ahead);
    c = k[0]; dt = k[1]; L = k[2]; inv_L = k[3];
    for (int q = 0; q < D; ++q) lo[q] = k[4 + q];
  }
  S moved(int64_t i, const S* f) const {
    S s = S(0);
    for (int q = 0; q < D; ++q) {
      const S u = (v[D*i + q] + f[q] * c) + f[q] * c;  // the two half-kicks
      S y = x[D*i + q] + u * dt;
      if (q == D - 1 && L > S(0)) y = y >= L ? y - L : (y < S(0) ? y + L : y);
      S d = (y - lo[q]) - ref[D*i + q];
      if (q == D - 1 && L > S(0)) d = d - drumheat::round_to_even(d * inv_L) * L;
      s = q ? s + d * d : d * d;
    }
    return s;
  }
};

// The pass that adds the chunks' sums (run, sum_range) for the particles whose data lie at
// [p0, p1): each particle's sums of all chunks, added in chunk order (the order of the terms of
// each sum does not depend on how the particles are cut), put back in the particles' numbering
// with the cell order, and the body force; then what needs the particle's force (finish): this
// step's x', v', w' written out from the records (Carry::drifted), the coming step's skin test
// (the range's largest squared displacement is returned) and the coming step's kicks, drift
// and records (Carry::next), the accumulators zeroed where they were read (also with next)
template <typename S, int D>
struct Sums {
  static constexpr int DW = D == 3 ? 3 : 1;
  // all by value, and copied once more into each range's pass (sum_range), so that the
  // compiler need not load them again after each value it stores
  Ahead<S, D> ahead;
  Drift<S, D> coming;  // the coming step's kicks and drift: this step's, a = 1 (header)
  S *xr, *vw, *rho;  // the records (Carry)
  bool drifted, next, rot, heat_on;
  const int32_t* od;  // the cell order (null: none)
  double* const* acc;  // the chunks' accumulators
  int64_t nc, n, fs, bs;
  S *F0, *T0;
  double* Q0;
  const S* body;
  S *X, *V, *W;  // outputs 17-19

  Sums(const Loop<S, D>& l, const Ahead<S, D>& ah, const Carry<S>& c, int64_t fs_,
       const int32_t* order)
      : ahead(ah), coming(l.a), xr(c.xr), vw(c.vw), rho(c.rho), drifted(c.drifted),
        next(c.next), rot(l.rot), heat_on(l.heat_on), od(order), acc(c.accp.data()),
        nc(static_cast<int64_t>(c.accp.size())), n(l.n), fs(fs_), bs(l.a.body_step),
        F0(static_cast<S*>(l.a.F)), T0(static_cast<S*>(l.a.T)), Q0(l.a.Q),
        body(static_cast<const S*>(l.a.body)), X(static_cast<S*>(l.a.DX)),
        V(static_cast<S*>(l.a.DV)), W(static_cast<S*>(l.a.DWo)) {
    coming.a = S(1);
  }

  // particle u, whose data lie at p, once its force and torque are summed (see above)
  __attribute__((always_inline)) inline S finish(int64_t p, int64_t u, S far) const {
    S* x = xr + XR*p;
    S* vs = vw + VW*p;
    if (drifted) {
      for (int q = 0; q < D; ++q) { X[D*u + q] = x[q]; V[D*u + q] = vs[q]; }
      for (int q = 0; q < DW; ++q) W[DW*u + q] = vs[D + q];
    }
    if (ahead.on) far = std::max(far, ahead.moved(u, F0 + D*u));
    if (next) {
      coming.advance(x, vs, vs + D, F0 + D*u, T0 + DW*u, rot, x, vs, vs + D);
      if (rho) rho[p] = std::sqrt(std::fma(x[0], x[0], x[1]*x[1]));  // as pack_range
    }
    return far;
  }
};

template <typename S, int D>
DRUMHEAT_FMA_CLONES S sum_range(const Sums<S, D>& all, int64_t p0, int64_t p1) {
  constexpr int DW = Sums<S, D>::DW;
  const Sums<S, D> sm = all;
  const int64_t n = sm.n, fs = sm.fs, nc = sm.nc;
  S far = S(0);
  for (int64_t p = p0; p < p1; ++p) {
    const int64_t u = sm.od ? sm.od[p] : p;  // the particle whose data lie at p
    S f[D], t[DW];
    double q = 0;
    for (int64_t c = 0; c < nc; ++c) {
      double* b = sm.acc[c];
      S* g = reinterpret_cast<S*>(b);
      for (int k = 0; k < D; ++k) f[k] = c ? f[k] + g[D*p + k] : g[D*p + k];
      for (int k = 0; k < DW; ++k) t[k] = c ? t[k] + g[D*n + DW*p + k] : g[D*n + DW*p + k];
      if (sm.heat_on) q = c ? q + b[fs + p] : b[fs + p];
      if (sm.next) {  // zeroed for the coming step
        for (int k = 0; k < D; ++k) g[D*p + k] = S(0);
        for (int k = 0; k < DW; ++k) g[D*n + DW*p + k] = S(0);
        if (sm.heat_on) b[fs + p] = 0;
      }
    }
    for (int k = 0; k < D; ++k) sm.F0[D*u + k] = sm.body ? f[k] + sm.body[sm.bs*u + k] : f[k];
    for (int k = 0; k < DW; ++k) sm.T0[DW*u + k] = t[k];
    if (sm.heat_on) sm.Q0[u] = q;
    far = sm.finish(p, u, far);
  }
  return far;
}

// One step: the contacts of call a, with the layout and chunks sh, the team's threads and what
// the steps of the call carry (cy)
template <typename S, int D>
bool run(Team& team, const Shared& sh, const Call& a, Carry<S>& cy) {
  constexpr int DW = Loop<S, D>::DW;
  Loop<S, D> lp(a);
  const int64_t n = a.n;
  const bool heat_on = lp.heat_on;
  // with a cell order the pairs are taken in the list's order (grouped in the cell order by
  // the neighbour build), the chunks are ranges of ranks and sum at the ranks, and the sums are
  // put back in the particles' numbering at the end; every chunk sums into its own buffer
  const bool ranked = sh.ranked;
  const Chunks& ch = sh.ch;
  const int64_t nc = ch.nc;
  lp.TK = sh.temp;
  lp.RK = sh.rank;
  if (!cy.drifted) pack_particles<S, D>(team, lp, ranked ? a.order : nullptr, cy);
  lp.XRp = cy.xr;
  lp.VWp = cy.vw;
  lp.RHO = cy.rho;
  auto work = [&](const Chunks& ch, int64_t c, S* F, S* T, double* Q, double* R) -> S {
    if (!a.later) lp.padding(ch.pb[c], ch.pb[c + 1]);
    const S p = lp.pairs(ch.kb[c], ch.kb[c + 1], F, T, Q, R);
    const S q = lp.walls(ch.s0(c), ch.s1(c), F, T, R);
    return p > q ? p : q;
  };

  double* R0 = a.R;
  S* MX = static_cast<S*>(a.MX);
  // a buffer holds the (D + DW) N forces and torques in its first fs doubles, then N doubles
  // of conduction heat (with it: nq = N), then 3 of loss rates
  const int64_t fs = (static_cast<int64_t>(sizeof(S)) * (D + DW) * n + 7) / 8;
  const int64_t nq = heat_on ? n : 0;
  if (cy.acc.empty()) {
    cy.acc.resize(nc);
    for (auto& b : cy.acc) {
      b = take_buffer(fs + nq + 3);
      cy.accp.push_back(b->data());
    }
  }
  std::vector<S> mx(nc, S(0));
  team.each([&](int c) {
    double* b = cy.acc[c]->data();
    S* F = reinterpret_cast<S*>(b);
    S* T = F + D * n;
    double *Q = b + fs, *R = b + fs + nq;
    if (!cy.drifted) {  // (else zeroed by the step before's sum pass)
      std::memset(F, 0, sizeof(S) * D * n);
      std::memset(T, 0, sizeof(S) * DW * n);
      if (heat_on) std::memset(Q, 0, sizeof(double) * n);
    }
    std::memset(R, 0, sizeof(double) * 3);
    mx[c] = work(ch, c, F, T, Q, R);
  });
  S max_ov = mx[0];
  for (int64_t c = 1; c < nc; ++c)
    if (mx[c] > max_ov) max_ov = mx[c];
  const Ahead<S, D> ahead(a);
  const Sums<S, D> sm(lp, ahead, cy, fs, ranked ? a.order : nullptr);
  std::vector<S> far(nc, S(0));  // each range's largest squared displacement (skin test)
  team.each([&](int cc) { far[cc] = sum_range<S, D>(sm, n*cc/nc, n*(cc + 1)/nc); });
  for (int q = 0; q < 3; ++q) {  // the loss rates, added in chunk order
    double r = 0;
    for (int64_t c = 0; c < nc; ++c) {
      const double rc = cy.acc[c]->data()[fs + nq + q];
      r = c ? r + rc : rc;
    }
    R0[q] = r;
  }
  cy.drifted = cy.next;
  MX[0] = max_ov;
  if (ahead.on) {
    S most = S(0);
    for (const S d : far) most = std::max(most, d);
    static_cast<S*>(a.AH)[0] = most;
  }
  return true;
}

// A run of steps (input 26, see the header): the call's step, then while fewer than K steps
// are made and the coming step's skin test passes, the next one, each from the outputs of the
// one before (its positions, half-step velocities and spins, forces, torques and springs; the
// pending half-kick's factor 1), with the slots' counts of the steps they conduct and the
// largest overlap ratio of all steps
template <typename S, int D>
bool run_steps(ffi::ThreadPool& pool, const Call& a) {
  Shared sh;
  if (!share(pool, a.P, a.order, a.n, a.m, a.nw, sh)) return false;
  Team team(pool, sh.ch.nc);
  gather_temperatures(team, a, sh);
  Carry<S> cy;
  if (!a.steps) return run<S, D>(team, sh, a, cy);
  const S* st = static_cast<const S*>(a.steps);
  const int64_t most = static_cast<int64_t>(st[0]);
  const S half_skin2 = st[1];
  std::memset(a.PC, 0, sizeof(int32_t) * a.m);
  if (a.WC) std::memset(a.WC, 0, sizeof(int32_t) * a.n * a.nw);
  Call b = a;
  S kick[5];
  std::memcpy(kick, a.drift, sizeof(kick));
  kick[0] = S(1);  // every step after the first: its predecessor's last half-kick pending
  S* MX = static_cast<S*>(a.MX);
  S mx = S(0);
  int32_t done = 0;
  while (true) {
    cy.next = done + 1 < most;  // another step, unless this one's skin test stops the run
    if (!run<S, D>(team, sh, b, cy)) return false;
    ++done;
    const S m = MX[0];
    if (m > mx || m != m) mx = m;  // (a NaN carried, as jnp.maximum)
    if (done >= most || static_cast<const S*>(a.AH)[0] > half_skin2) break;
    b.x = b.DX; b.v = b.DV; b.w = b.DWo; b.df = b.F; b.dtq = b.T; b.sp = b.S; b.ws = b.WS;
    b.drift = kick;
    b.later = true;
  }
  MX[0] = mx;
  a.DONE[0] = done;
  return true;
}

// the buffers of one call of the friction heat's second pass (ContactHeatImpl)
struct HeatCall {
  const void *v, *w, *PW, *WW, *wv, *wom;
  const int32_t *P, *order;  // order: as Call::order (null: none), for the chunks only
  const double* K;  // conductivities (N), or null: half and half
  double *E, *SUM;
  int64_t n, m, nw;
  double dt, kw;
};

// Friction heat, second pass (see the header): each contact's loss D at the full-step
// velocities from the rows of the first pass, split between its partners (dissipation.step_heat)
template <typename S, int D>
bool heat_pass(ffi::ThreadPool& pool, const HeatCall& a) {
  constexpr int DW = D == 3 ? 3 : 1;
  constexpr int KP = 3*D + DW + 1, KW = 2*D + DW + 1;
  const int64_t n = a.n, m = a.m, nw = a.nw;
  const S *v = static_cast<const S*>(a.v), *w = static_cast<const S*>(a.w);
  const S *PW = static_cast<const S*>(a.PW), *WW = static_cast<const S*>(a.WW);
  const S *WV = static_cast<const S*>(a.wv), *WOM = static_cast<const S*>(a.wom);
  const int32_t* P = a.P;
  const double *K = a.K, dt = a.dt, kw = a.kw;
  // E (N) the particles' heat, sums[0] the walls', sums[1] all of it
  auto work = [&](int64_t k0, int64_t k1, int64_t s0, int64_t s1, double* E, double* sums) {
    for (int64_t k = k0; k < k1; ++k) {
      const int32_t i = P[k], j = P[m + k];
      if (i >= n) continue;
      const S* h = PW + KP*k;  // force, lever_i, lever_j, rolling torque, dU
      S ci[D], cj[D], pw = S(0), pr = S(0);
      spin_cross<S, D>(w + DW*i, h + D, ci);
      spin_cross<S, D>(w + DW*j, h + 2*D, cj);
      for (int c = 0; c < D; ++c) pw += h[c]*((v[D*j + c] + cj[c]) - (v[D*i + c] + ci[c]));
      for (int c = 0; c < DW; ++c) pr += h[3*D + c]*(w[DW*j + c] - w[DW*i + c]);
      const double loss = -dt*(double(pw) + double(pr)) - double(h[KP - 1]);
      const double share = K ? K[i] / (K[i] + K[j]) : 0.5;
      E[i] += share*loss; E[j] += (1.0 - share)*loss; sums[1] += loss;
    }
    for (int64_t q = s0; q < s1; ++q) {
      const int64_t p = q / nw;
      const S* h = WW + KW*q;  // force, lever, rolling torque, dU
      S cw[D], pw = S(0), pr = S(0);
      spin_cross<S, D>(w + DW*p, h + D, cw);
      for (int c = 0; c < D; ++c) pw += h[c]*(v[D*p + c] + cw[c] - WV[D*q + c]);
      for (int c = 0; c < DW; ++c)
        pr += h[2*D + c]*(w[DW*p + c] - (c == DW - 1 ? WOM[q % nw] : S(0)));
      const double loss = -dt*(double(pw) + double(pr)) - double(h[KW - 1]);
      const double share = K ? K[p] / (K[p] + kw) : 0.5;
      E[p] += share*loss; sums[0] += (1.0 - share)*loss; sums[1] += loss;
    }
  };
  double *E0 = a.E, *S0 = a.SUM;
  std::memset(E0, 0, sizeof(double) * n);
  S0[0] = S0[1] = 0.0;
  // the chunks as the first pass cuts them
  Shared sh;
  if (!share(pool, P, a.order, n, m, nw, sh)) return false;
  const Chunks& ch = sh.ch;
  const int64_t nc = ch.nc;
  std::vector<std::unique_ptr<Buffer>> acc(nc - 1);
  for (auto& b : acc) b = take_buffer(n + 2);
  Team team(pool, nc);
  team.each([&](int c) {
    double *E = E0, *sums = S0;
    if (c > 0) {
      E = acc[c - 1]->data(); sums = E + n;
      std::memset(E, 0, sizeof(double) * (n + 2));
    }
    work(ch.kb[c], ch.kb[c + 1], ch.s0(c), ch.s1(c), E, sums);
  });
  for (int64_t c = 1; c < nc; ++c) {
    const double* b = acc[c - 1]->data();
    for (int64_t q = 0; q < n; ++q) E0[q] += b[q];
    S0[0] += b[n]; S0[1] += b[n + 1];
  }
  for (auto& b : acc) give_buffer(std::move(b));
  return true;
}

}  // namespace

static ffi::Error ContactsImpl(
    ffi::ThreadPool pool, ffi::AnyBuffer pos, ffi::AnyBuffer vel, ffi::AnyBuffer omg,
    ffi::AnyBuffer rad, ffi::AnyBuffer mass, ffi::AnyBuffer inertia, ffi::Buffer<ffi::S32> ptype,
    ffi::Buffer<ffi::S32> pairs, ffi::AnyBuffer spring, ffi::AnyBuffer wdist, ffi::AnyBuffer wnrm,
    ffi::AnyBuffer wvel, ffi::AnyBuffer wspring, ffi::AnyBuffer tab_pp, ffi::AnyBuffer tab_pw,
    ffi::AnyBuffer wall_omega, ffi::Buffer<ffi::F64> temp, ffi::AnyBuffer wdist0,
    ffi::Buffer<ffi::S32> order, ffi::AnyBuffer body, ffi::AnyBuffer ahead, ffi::AnyBuffer ref,
    ffi::AnyBuffer shell, ffi::AnyBuffer drift, ffi::AnyBuffer dforce, ffi::AnyBuffer dtorque,
    ffi::AnyBuffer run_of_steps, double dt,
    double L, int32_t law, double h, double tol, int32_t rot, int32_t fh, double cgap,
    double wgap,
    ffi::Result<ffi::AnyBuffer> force, ffi::Result<ffi::AnyBuffer> torque,
    ffi::Result<ffi::AnyBuffer> nspring, ffi::Result<ffi::AnyBuffer> ovl_out,
    ffi::Result<ffi::AnyBuffer> dist_out, ffi::Result<ffi::AnyBuffer> fn_out,
    ffi::Result<ffi::AnyBuffer> nwspring, ffi::Result<ffi::AnyBuffer> wovl_out,
    ffi::Result<ffi::AnyBuffer> wfn_out, ffi::Result<ffi::AnyBuffer> max_ratio,
    ffi::ResultBuffer<ffi::F64> heat, ffi::ResultBuffer<ffi::PRED> conducts,
    ffi::Result<ffi::AnyBuffer> pair_rows,
    ffi::Result<ffi::AnyBuffer> wall_rows, ffi::ResultBuffer<ffi::F64> rates,
    ffi::Result<ffi::AnyBuffer> ahead_out, ffi::ResultBuffer<ffi::PRED> wall_conducts,
    ffi::Result<ffi::AnyBuffer> dpos, ffi::Result<ffi::AnyBuffer> dvel,
    ffi::Result<ffi::AnyBuffer> domg, ffi::ResultBuffer<ffi::S32> pair_counts,
    ffi::ResultBuffer<ffi::S32> wall_counts, ffi::ResultBuffer<ffi::S32> done) {
  const ffi::DataType et = pos.element_type();
  if (et != ffi::DataType::F32 && et != ffi::DataType::F64)
    return ffi::Error::InvalidArgument("drumheat_contacts: positions must be f32 or f64");
  for (const ffi::AnyBuffer* b : {&vel, &omg, &rad, &mass, &inertia, &spring, &wdist, &wnrm,
                                  &wvel, &wspring, &tab_pp, &tab_pw, &wall_omega, &wdist0,
                                  &body, &ahead, &ref, &shell, &drift, &dforce, &dtorque,
                                  &run_of_steps})
    if (b->element_type() != et)
      return ffi::Error::InvalidArgument("drumheat_contacts: mixed float dtypes");
  for (ffi::Result<ffi::AnyBuffer>* b : {&force, &torque, &nspring, &ovl_out, &dist_out,
                                               &fn_out, &nwspring, &wovl_out, &wfn_out,
                                               &max_ratio, &pair_rows, &wall_rows,
                                               &ahead_out, &dpos, &dvel, &domg})
    if ((*b)->element_type() != et)
      return ffi::Error::InvalidArgument("drumheat_contacts: mixed float dtypes");
  const auto pd = pos.dimensions();
  if (pd.size() != 2 || (pd[1] != 2 && pd[1] != 3))
    return ffi::Error::InvalidArgument("drumheat_contacts: positions must be (N, 2) or (N, 3)");
  const int dim = static_cast<int>(pd[1]);
  Call a;
  a.x = pos.untyped_data(); a.v = vel.untyped_data(); a.w = omg.untyped_data();
  a.r = rad.untyped_data(); a.ms = mass.untyped_data(); a.in = inertia.untyped_data();
  a.sp = spring.untyped_data(); a.wd = wdist.untyped_data(); a.wn = wnrm.untyped_data();
  a.wv = wvel.untyped_data(); a.ws = wspring.untyped_data(); a.tpp = tab_pp.untyped_data();
  a.tpw = tab_pw.untyped_data(); a.wom = wall_omega.untyped_data();
  a.wd0 = wdist0.untyped_data();
  a.pt = ptype.typed_data(); a.P = pairs.typed_data(); a.temp = temp.typed_data();
  a.order = order.element_count() ? order.typed_data() : nullptr;
  a.F = force->untyped_data(); a.T = torque->untyped_data(); a.S = nspring->untyped_data();
  // the per-pair overlaps, distances and normal forces: all three of length M, or all three
  // of length 0 (not written)
  const bool details = ovl_out->element_count() != 0;
  a.OV = details ? ovl_out->untyped_data() : nullptr;
  a.DI = details ? dist_out->untyped_data() : nullptr;
  a.FN = details ? fn_out->untyped_data() : nullptr;
  a.WS = nwspring->untyped_data();
  a.WO = wovl_out->untyped_data(); a.WF = wfn_out->untyped_data();
  a.MX = max_ratio->untyped_data(); a.Q = heat->typed_data(); a.CD = conducts->typed_data();
  a.PW = pair_rows->untyped_data(); a.WW = wall_rows->untyped_data(); a.R = rates->typed_data();
  a.n = pd[0];
  a.m = pairs.dimensions()[1];
  const auto wsd = wspring.dimensions();
  a.nw = wsd.size() > 1 ? wsd[1] : 0;
  a.nt = tab_pp.dimensions()[1];
  // radius, mass, inertia: one per particle, or one for all (stride 0); the types: one per
  // particle, or none read with one type
  int64_t* steps[] = {&a.r_step, &a.ms_step, &a.in_step};
  const ffi::AnyBuffer* per[] = {&rad, &mass, &inertia};
  for (int q = 0; q < 3; ++q) {
    const int64_t k = static_cast<int64_t>(per[q]->element_count());
    if (k != a.n && k != 1)
      return ffi::Error::InvalidArgument("drumheat_contacts: radius, mass and inertia must "
                                         "have length N or 1");
    *steps[q] = k == a.n ? 1 : 0;
  }
  if (static_cast<int64_t>(ptype.element_count()) != a.n && a.nt != 1)
    return ffi::Error::InvalidArgument("drumheat_contacts: the types must have length N "
                                       "(or any with one type)");
  a.dt = dt; a.L = L; a.h = h; a.tol = tol; a.law = law; a.rot = rot != 0; a.fh = fh != 0;
  a.cgap = cgap; a.wgap = wgap;
  // the geometry given for the walls: all W, or W - 1 with the drum shell (wall 0)
  const bool with_shell = shell.element_count() != 0;
  if (with_shell && (shell.element_count() != 2 || a.nw < 1 || a.fh))
    return ffi::Error::InvalidArgument("drumheat_contacts: the drum shell takes (R, omega) and "
                                       "a first wall, without friction heat");
  const int64_t ng = with_shell ? a.nw - 1 : a.nw;
  const int64_t gd = wdist.dimensions().size() > 1 ? wdist.dimensions()[1] : 0;
  if (static_cast<int64_t>(wdist.element_count()) != a.n * ng || (a.n && gd != ng) ||
      static_cast<int64_t>(wnrm.element_count()) != a.n * ng * dim ||
      static_cast<int64_t>(wvel.element_count()) != a.n * ng * dim)
    return ffi::Error::InvalidArgument("drumheat_contacts: the wall geometry must be given for "
                                       "every wall but the drum shell");
  a.shell = with_shell ? shell.untyped_data() : nullptr;
  const int64_t ncw = static_cast<int64_t>(wall_conducts->element_count());
  if (ncw != 0 && ncw != a.n * a.nw)
    return ffi::Error::InvalidArgument("drumheat_contacts: the wall slots' conduction flags "
                                       "must be (N, W) or of length 0");
  a.CW = ncw ? wall_conducts->typed_data() : nullptr;
  if (drift.element_count() != 0) {
    const int64_t nd = a.n * dim, nr = a.n * (dim == 3 ? 3 : 1);
    if (drift.element_count() != 5 || static_cast<int64_t>(dforce.element_count()) != nd ||
        static_cast<int64_t>(dtorque.element_count()) != nr ||
        static_cast<int64_t>(dpos->element_count()) != nd ||
        static_cast<int64_t>(dvel->element_count()) != nd ||
        static_cast<int64_t>(domg->element_count()) != nr)
      return ffi::Error::InvalidArgument("drumheat_contacts: the step's drift takes 5 constants, "
                                         "the forces and torques before, and three outputs");
    if (a.fh || !(a.nw == 0 || (with_shell && a.nw == 1)))
      return ffi::Error::InvalidArgument("drumheat_contacts: the step's drift takes no walls "
                                         "but the drum shell, and no friction heat");
    a.drift = drift.untyped_data(); a.df = dforce.untyped_data(); a.dtq = dtorque.untyped_data();
    a.DX = dpos->untyped_data(); a.DV = dvel->untyped_data(); a.DWo = domg->untyped_data();
  }
  const int dw = dim == 3 ? 3 : 1;
  if (a.fh && (static_cast<int64_t>(pair_rows->element_count()) != a.m * (3*dim + dw + 1) ||
               static_cast<int64_t>(wall_rows->element_count()) != a.n * a.nw * (2*dim + dw + 1) ||
               static_cast<int64_t>(wdist0.element_count()) != a.n * a.nw))
    return ffi::Error::InvalidArgument("drumheat_contacts: friction heat rows of wrong size");
  for (ffi::Result<ffi::AnyBuffer>* b : {&ovl_out, &dist_out, &fn_out})
    if (static_cast<int64_t>((*b)->element_count()) != (details ? a.m : 0))
      return ffi::Error::InvalidArgument("drumheat_contacts: the per-pair overlap, distance and "
                                         "normal force must all have length M or all length 0");
  if (a.order && static_cast<int64_t>(order.element_count()) != a.n)
    return ffi::Error::InvalidArgument("drumheat_contacts: the cell order must have length N or 0");
  const int64_t nb = static_cast<int64_t>(body.element_count());
  if (nb != 0 && nb != dim && nb != a.n * dim)
    return ffi::Error::InvalidArgument("drumheat_contacts: the body force must be (N, D), (1, D) "
                                       "or of length 0");
  a.body = nb ? body.untyped_data() : nullptr;
  a.body_step = nb == a.n * dim && a.n > 1 ? dim : 0;
  if (ahead.element_count() != 0) {
    if (static_cast<int64_t>(ahead.element_count()) != 4 + dim ||
        static_cast<int64_t>(ref.element_count()) != a.n * dim || ahead_out->element_count() != 1)
      return ffi::Error::InvalidArgument("drumheat_contacts: the skin test takes 4 + D "
                                         "constants, (N, D) reference positions, one output");
    a.ahead = ahead.untyped_data(); a.ref = ref.untyped_data();
    a.AH = ahead_out->untyped_data();
  }
  if (run_of_steps.element_count() != 0) {
    if (run_of_steps.element_count() != 2 || !a.drift || !a.ahead || (a.nw && !a.CW) ||
        static_cast<int64_t>(pair_counts->element_count()) != a.m ||
        static_cast<int64_t>(wall_counts->element_count()) != a.n * a.nw ||
        done->element_count() != 1)
      return ffi::Error::InvalidArgument("drumheat_contacts: a run of steps takes K and half "
                                         "the skin squared, the drift, the skin test, the wall "
                                         "slots' flags and three outputs");
    a.steps = run_of_steps.untyped_data();
    a.PC = pair_counts->typed_data(); a.WC = a.nw ? wall_counts->typed_data() : nullptr;
    a.DONE = done->typed_data();
  }
  const bool f64 = et == ffi::DataType::F64;
  bool ok;
  if (dim == 3) ok = f64 ? run_steps<double, 3>(pool, a) : run_steps<float, 3>(pool, a);
  else ok = f64 ? run_steps<double, 2>(pool, a) : run_steps<float, 2>(pool, a);
  if (!ok)
    return ffi::Error::InvalidArgument("drumheat_contacts: the cell order is not a permutation "
                                       "of the particles");
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    Contacts, ContactsImpl,
    ffi::Ffi::Bind()
        .Ctx<ffi::ThreadPool>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>()
        .Arg<ffi::Buffer<ffi::S32>>().Arg<ffi::Buffer<ffi::S32>>()
        .Arg<ffi::AnyBuffer>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>()
        .Arg<ffi::Buffer<ffi::F64>>().Arg<ffi::AnyBuffer>().Arg<ffi::Buffer<ffi::S32>>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>()
        .Arg<ffi::AnyBuffer>()
        .Attr<double>("dt").Attr<double>("L").Attr<int32_t>("law").Attr<double>("h")
        .Attr<double>("tol").Attr<int32_t>("rot").Attr<int32_t>("fh").Attr<double>("cgap")
        .Attr<double>("wgap")
        .Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>()
        .Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>()
        .Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>()
        .Ret<ffi::AnyBuffer>().Ret<ffi::Buffer<ffi::F64>>().Ret<ffi::Buffer<ffi::PRED>>()
        .Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>().Ret<ffi::Buffer<ffi::F64>>()
        .Ret<ffi::AnyBuffer>().Ret<ffi::Buffer<ffi::PRED>>()
        .Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>().Ret<ffi::AnyBuffer>()
        .Ret<ffi::Buffer<ffi::S32>>().Ret<ffi::Buffer<ffi::S32>>().Ret<ffi::Buffer<ffi::S32>>());

// The friction heat's second pass (ContactHeat; see the header).
static ffi::Error ContactHeatImpl(
    ffi::ThreadPool pool, ffi::AnyBuffer vel, ffi::AnyBuffer omg, ffi::Buffer<ffi::S32> pairs,
    ffi::AnyBuffer pair_rows, ffi::AnyBuffer wall_rows, ffi::AnyBuffer wvel,
    ffi::AnyBuffer wall_omega, ffi::Buffer<ffi::F64> cond, ffi::Buffer<ffi::S32> order,
    double dt, double kw, ffi::ResultBuffer<ffi::F64> heat, ffi::ResultBuffer<ffi::F64> sums) {
  const ffi::DataType et = vel.element_type();
  if (et != ffi::DataType::F32 && et != ffi::DataType::F64)
    return ffi::Error::InvalidArgument("drumheat_contact_heat: velocities must be f32 or f64");
  for (const ffi::AnyBuffer* b : {&omg, &pair_rows, &wall_rows, &wvel, &wall_omega})
    if (b->element_type() != et)
      return ffi::Error::InvalidArgument("drumheat_contact_heat: mixed float dtypes");
  const auto vd = vel.dimensions();
  if (vd.size() != 2 || (vd[1] != 2 && vd[1] != 3))
    return ffi::Error::InvalidArgument("drumheat_contact_heat: velocities must be (N, 2) or "
                                       "(N, 3)");
  const int dim = static_cast<int>(vd[1]), dw = dim == 3 ? 3 : 1;
  HeatCall a;
  a.n = vd[0];
  a.m = pairs.dimensions()[1];
  a.nw = wall_omega.element_count();
  if (static_cast<int64_t>(pair_rows.element_count()) != a.m * (3*dim + dw + 1) ||
      static_cast<int64_t>(wall_rows.element_count()) != a.n * a.nw * (2*dim + dw + 1) ||
      static_cast<int64_t>(wvel.element_count()) != a.n * a.nw * dim ||
      (cond.element_count() != 0 && static_cast<int64_t>(cond.element_count()) != a.n) ||
      (order.element_count() != 0 && static_cast<int64_t>(order.element_count()) != a.n))
    return ffi::Error::InvalidArgument("drumheat_contact_heat: buffers of wrong size");
  a.order = order.element_count() ? order.typed_data() : nullptr;
  a.v = vel.untyped_data(); a.w = omg.untyped_data(); a.P = pairs.typed_data();
  a.PW = pair_rows.untyped_data(); a.WW = wall_rows.untyped_data();
  a.wv = wvel.untyped_data(); a.wom = wall_omega.untyped_data();
  a.K = cond.element_count() ? cond.typed_data() : nullptr;
  a.E = heat->typed_data(); a.SUM = sums->typed_data();
  a.dt = dt; a.kw = kw;
  const bool f64 = et == ffi::DataType::F64;
  bool ok;
  if (dim == 3) ok = f64 ? heat_pass<double, 3>(pool, a) : heat_pass<float, 3>(pool, a);
  else ok = f64 ? heat_pass<double, 2>(pool, a) : heat_pass<float, 2>(pool, a);
  if (!ok)
    return ffi::Error::InvalidArgument("drumheat_contact_heat: the cell order is not a "
                                       "permutation of the particles");
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    ContactHeat, ContactHeatImpl,
    ffi::Ffi::Bind()
        .Ctx<ffi::ThreadPool>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::Buffer<ffi::S32>>()
        .Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>().Arg<ffi::AnyBuffer>()
        .Arg<ffi::Buffer<ffi::F64>>().Arg<ffi::Buffer<ffi::S32>>()
        .Attr<double>("dt").Attr<double>("kw")
        .Ret<ffi::Buffer<ffi::F64>>().Ret<ffi::Buffer<ffi::F64>>());

// The coupled heat's contact conduction (CountConduction; see the header).
static ffi::Error CountConductionImpl(ffi::Buffer<ffi::F64> temp, ffi::Buffer<ffi::F64> diam,
                                      ffi::Buffer<ffi::F64> alpha, ffi::Buffer<ffi::S32> pairs,
                                      ffi::Buffer<ffi::S32> counts, double dt, double h,
                                      ffi::ResultBuffer<ffi::F64> heat) {
  const int64_t n = static_cast<int64_t>(temp.element_count());
  const int64_t m = static_cast<int64_t>(counts.element_count());
  const auto pd = pairs.dimensions();
  if (static_cast<int64_t>(diam.element_count()) != n || alpha.element_count() != 1 ||
      pd.size() != 2 || pd[0] != 2 || pd[1] != m ||
      static_cast<int64_t>(heat->element_count()) != n)
    return ffi::Error::InvalidArgument("drumheat_count_conduction: buffers of wrong size");
  const double* T = temp.typed_data();
  const double* d = diam.typed_data();
  const double a = alpha.typed_data()[0];
  const int32_t* I = pairs.typed_data();
  const int32_t* J = I + m;
  const int32_t* C = counts.typed_data();
  double* Q = heat->typed_data();
  const double unit = dt / h;  // a step's fraction of the thermal step (no division per slot)
  std::fill(Q, Q + n, 0.0);
  for (int64_t k = 0; k < m; ++k) {
    // every listed slot, its count 0 or not: a test of the count mispredicts where the
    // conducting slots alternate with the others (about half of them in a turning bed), and
    // a count 0 adds 0, as the JAX sum's slot does
    const int64_t i = I[k], j = J[k];
    if (i < 0 || j < 0 || i >= n || j >= n) continue;  // padding (at the list's end)
    const double f = conductance(0, a, 0.5 * d[i], 0.5 * d[j], 0.0) * (C[k] * unit) *
                     (T[j] - T[i]);
    Q[i] += f;
    Q[j] -= f;
  }
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    CountConduction, CountConductionImpl,
    ffi::Ffi::Bind()
        .Arg<ffi::Buffer<ffi::F64>>().Arg<ffi::Buffer<ffi::F64>>().Arg<ffi::Buffer<ffi::F64>>()
        .Arg<ffi::Buffer<ffi::S32>>().Arg<ffi::Buffer<ffi::S32>>()
        .Attr<double>("dt").Attr<double>("h")
        .Ret<ffi::Buffer<ffi::F64>>());
