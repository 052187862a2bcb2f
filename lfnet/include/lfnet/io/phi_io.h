// The calibrated-Phi folder: a measured per-pixel angular response as images plus a JSON
// sidecar, accepted wherever --phi is. The format is described in docs/acquisition.md
// ("Calibrated Phi").
#pragma once

#include <string>
#include <vector>

#include "lfnet/optics/phi.h"

namespace lfnet::io {

constexpr int kCalibratedPhiFormatVersion = 1;
constexpr const char* kCalibratedPhiFormat = "lfnet-calibrated-phi";
constexpr const char* kCalibratedPhiSidecar = "phi.json";

// Whether `path` is a calibrated-Phi folder (one holding phi.json) or a sidecar file (JSON
// whose "format" is lfnet-calibrated-phi, whatever its name).
bool is_calibrated_phi(const std::string& path);

// Writes a local Phi into the folder `dir` (created if missing; files of the same names are
// replaced, so callers choose the output policy):
// phi.json and one float64 TIFF per measurement, response_<n>.tif (n from 1), of
// (T U) x (T V) pixels, in which the U x V block at block row y, block column x holds the
// weights M_n(u, v) of sensor pixel (y, x) of the period T. The weights are written as the
// model computes them (already normalised), so loading the folder gives the same Phi.
// Random projections are not local and cannot be written (ConfigError).
void write_calibrated_phi(const optics::Phi& phi, const std::string& dir);

// The pattern to print for a mask or aperture code: per measurement, mask_<n>.png (n from 1), an
// 8-bit grey image in the layout of response_<n>.tif, each weight over the code's largest (white:
// fully open, black: opaque), the transmittances of a learned mask up to its one normalising
// scale. Negative weights have no transmittance (ConfigError), nor has a Phi that is not local.
// Returns the names written into `dir` (created if missing).
std::vector<std::string> write_printable_mask(const optics::Phi& phi, const std::string& dir);

// Whether `phi` is a learned mask or aperture (a `calibrated` spec whose source says so), whose
// export comes with its printable pattern.
bool is_learned_mask(const optics::Phi& phi);

// Reads a calibrated-Phi folder (or its sidecar file, whose images lie beside it) into the spec of
// a "calibrated" Phi, whose params carry every weight: models and acquisitions made with it record
// the camera itself. Throws IoError naming the file for anything malformed, before any image is
// decoded where the sidecar alone shows it.
optics::PhiSpec read_calibrated_phi(const std::string& path);

}  // namespace lfnet::io
