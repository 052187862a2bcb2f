// The Angle Sensitive Pixel table: which (beta, gamma, alpha) each of the N measurements uses.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace lfnet::optics {

// One ASP measurement channel: M(u, v) = A(u, v) (1 + m cos(beta (cos(gamma) theta_u +
// sin(gamma) phi_v) + alpha)) / 2, theta_u and phi_v the view angles normalised to [-1, 1].
struct AspRow {
  double beta = 0;      // angular frequency, radians per unit of theta
  double gamma = 0;     // orientation, radians, in [0, pi)
  double alpha = 0;     // phase, radians
  int64_t k_theta = 0;  // the frequency as a DFT index along U ...
  int64_t k_phi = 0;    // ... and along V (beta (cos, sin)(gamma) = pi k (U-1)/U, pi k (V-1)/V)
  std::string role;     // "pair", "in-phase" or "quadrature"
};

// The first n rows of the ASP table of a rows x cols angular grid (docs/acquisition.md):
//   1. a complementary pair at 0 degrees, frequency 1, alpha = 0 and pi (together a
//      conventional pixel A(u, v));
//   2. then, ring by ring of DFT frequencies (max(|k_theta|, |k_phi|) = 1, 2, ...), first the
//      principal orientations 0/45/90/135 degrees, then the oblique ones, each group in-phase
//      (alpha = 0) by increasing gamma, then quadrature (alpha = pi / 2) by increasing gamma.
// Frequencies sit on the grid's DFT frequencies, so the rows are the grid's real Fourier
// basis plus a constant: at n = rows * cols the table spans every angular pattern. Quadrature
// rows of self-conjugate (Nyquist) frequencies vanish and are left out.
// With `pairs`, every row after the first pair is followed by its complement (alpha + pi), as
// in a tile of differential ASPs; the pair adds only the constant, so rank grows half as fast.
// `pair_gamma` and `pair_alpha` (degrees) choose the row of the complementary pair: (0, 0) is
// even in the view angle, so at N = 2 it cannot tell the sign of the parallax; the quadrature
// pair (alpha 90, the `asp` model's default) is odd and can. The table's
// other rows keep their order, without the pair's row, so the set of rows is unchanged.
std::vector<AspRow> asp_table(int64_t rows, int64_t cols, int64_t n, bool pairs = false,
                              double pair_gamma = 0.0, double pair_alpha = 0.0);

}  // namespace lfnet::optics
