// Calibration error: a camera whose Phi differs from the one its model was made for
// (docs/acquisition.md, "Calibration error"). A local Phi is described by its pixel weights
// M_n(u, v) at every sensor pixel; a calibration error changes them in four ways, each 0 when
// absent:
//   - modulation depth: each measurement's weights about their mean over the views are scaled
//     by 1 + depth (for the ASP model exactly its m, since the means over the views of its
//     cosines vanish on the view grid);
//   - angular shift: the angular response displaced by (angular_shift_u, angular_shift_v)
//     views, linearly interpolated between views and held at the grid's edge (a grating or
//     mask displaced against the photodiode or microlens shifts which rays a pixel favours);
//   - code shift and period: pixel (y, x) of the sensor takes the code's weights at code
//     position ((y + shift_y) (1 + period), (x + shift_x) (1 + period)), bilinear between the
//     pixels of the code's tile (only codes that vary across the sensor, period() > 1, change);
//   - vignetting: every measurement of the pixel is multiplied by 1 - vignetting r^2, r the
//     pixel's distance from the sensor's centre over its half-diagonal (so the corners lose
//     `vignetting` of their signal).
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <random>
#include <string>

#include "lfnet/core/fields.h"
#include "lfnet/optics/phi.h"

namespace lfnet::optics {

// One camera's error against its nominal Phi.
struct CalibrationError {
  double depth = 0;            // relative change of the modulation depth (0.1: 10 % deeper)
  double angular_shift_u = 0;  // the angular response displaced by this many views along U
  double angular_shift_v = 0;  // ... and along V
  double shift_y = 0;          // the code displaced against the pixels, in pixels
  double shift_x = 0;
  double period = 0;      // relative error of the code's period (0.01: 1 % longer)
  double vignetting = 0;  // share of the signal lost at the sensor's corners, in [0, 1)

  template <typename Fields>
  void fields(Fields& f) {
    f("depth", depth, Range::above(-1, 10));
    f("angular_shift_u", angular_shift_u, Range::closed(-1000, 1000));
    f("angular_shift_v", angular_shift_v, Range::closed(-1000, 1000));
    f("shift_y", shift_y, Range::closed(-1e4, 1e4));
    f("shift_x", shift_x, Range::closed(-1e4, 1e4));
    f("period", period);
    f("vignetting", vignetting);
  }
  bool empty() const;
  // Throws ConfigError naming the bad field.
  void validate() const;
  // Strict: unknown keys are ConfigErrors naming the JSON path.
  static CalibrationError from_json(const nlohmann::json& j, const std::string& path = "$");
  nlohmann::json to_json() const;
};

// The ranges training draws calibration errors from, one draw per patch (docs/architectures.md,
// "Calibration-robust training"): depth, each angular shift, each code shift and the period
// uniformly in [-range, range]; vignetting uniformly in [0, vignetting], the patch placed
// uniformly in a sensor `vignetting_sensor` times its size on each side.
struct CalibrationRanges {
  double depth = 0;
  double angular_shift = 0;  // views
  double shift = 0;          // pixels
  double period = 0;
  double vignetting = 0;
  double vignetting_sensor = 4;

  template <typename Fields>
  void fields(Fields& f) {
    f("depth", depth);
    f("angular_shift", angular_shift, Range::closed(0, 16));
    f("shift", shift, Range::closed(0, 1024));
    f("period", period);
    f("vignetting", vignetting);
    f("vignetting_sensor", vignetting_sensor, Range::closed(1, 1e6));
  }
  bool empty() const;
  void validate() const;
};

// Where a block of pixels lies on its sensor, for vignetting: the block's origin (y0, x0) on a
// sensor of sensor_h x sensor_w pixels (its code may be placed otherwise: a training patch's
// code phase comes from its light field, its place on a sensor is drawn).
struct SensorPlacement {
  int64_t y0 = 0, x0 = 0;
  int64_t sensor_h = 0, sensor_w = 0;
};

// The weights (N, U, V, h, w) of the pixels of the (h, w) block at code origin (y0, x0) of a
// camera with Phi `phi` (local) and calibration error `error`, vignetted as a block at
// `placement`; equal to phi.pixel_weights(y0, x0, h, w) when the error is empty.
torch::Tensor perturbed_pixel_weights(const Phi& phi, const CalibrationError& error, int64_t y0,
                                      int64_t x0, int64_t h, int64_t w,
                                      const SensorPlacement& placement,
                                      torch::ScalarType dtype = torch::kFloat32);

// The sensor image (..., N, H, W) of a light field (..., U, V, H, W) taken by that camera, no
// sensor effects; computed in bands of rows. Equals phi.forward(lf) when the error is empty.
torch::Tensor perturbed_forward(const Phi& phi, const CalibrationError& error,
                                const torch::Tensor& lf);

// Flat fields (docs/acquisition.md, "Flat field"): what a gain across the sensor, such as
// vignetting, does to every measurement of a pixel is undone by dividing by it, once it has been
// measured. The measurement is a white frame: the sensor image (N, H, W) of a uniform light field
// (a white diffuser, or `lfnet simulate --white HxW`) taken with the camera.

// The nominal camera's sensor image (N, H, W) of the uniform light field of value 1: a local
// Phi's weights summed over the views, tiled over the sensor by the code's period.
torch::Tensor nominal_white(const Phi& phi, int64_t height, int64_t width);

// The gain (H, W) of each sensor pixel from a white frame (N, H, W) of any exposure: the sum of
// the pixel's measurements over the nominal camera's (`nominal`, from nominal_white), divided by
// the peak of a quadratic surface fitted to that ratio by least squares, so that the brightest
// part of the sensor (vignetting's optical centre) has gain 1 without reading any one noisy
// pixel. A pixel whose nominal measurements are all 0 (a mask opaque at every shot) keeps gain 1.
// Throws ConfigError when the shapes differ or the frame has no light.
torch::Tensor flat_field_gain(const torch::Tensor& white, const torch::Tensor& nominal);

// The sensor image (..., N, H, W) with each measurement divided by its pixel's gain (H, W)
// (at least 1e-3). Throws ConfigError when the sizes differ, naming both.
torch::Tensor apply_flat_field(const torch::Tensor& sensor, const torch::Tensor& gain);

}  // namespace lfnet::optics
