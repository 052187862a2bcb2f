// The noise of a coded sensor image, estimated from the image alone (docs/acquisition.md,
// "Estimating the noise"): what a noise-aware model is told when the user does not know it.
#pragma once

#include <torch/types.h>

#include "lfnet/optics/phi.h"

namespace lfnet::optics {

// The Gaussian noise sigma of a sensor image (N, H, W), relative to a white scene's signal
// (lfnet's Phis measure 1 on average for white, phi.h). `white` (N, T, T) is what each pixel
// phase of the code's period T measures of a white light field. Each measurement is divided by
// its pixels' white response, which leaves a smooth image where the scene is (the code's own
// pixel pattern is no noise), and the noise is Donoho and Johnstone's estimate on it: the
// median absolute finest-scale diagonal Haar wavelet coefficient over 0.6745 (Donoho &
// Johnstone, "Ideal spatial adaptation by wavelet shrinkage", Biometrika 1994), each
// coefficient scaled by the noise its four pixels carry after the division. Pixels whose white
// response is below a fifth of the mean carry too much noise and are left out. Under shot and
// read noise it estimates the sigma at about the image's median signal; scene detail finer than
// a pixel adds a little of its own. A sensor image too small for one coefficient is a
// ConfigError.
double estimate_noise_sigma(const torch::Tensor& sensor, const torch::Tensor& white);

// The same for a local Phi (phi.h, is_local): its white response from pixel_weights.
double estimate_noise_sigma(const Phi& phi, const torch::Tensor& sensor);

// The share of estimate_noise_sigma that is white noise, independent from pixel to pixel as a
// sensor's own noise is, in [0, 1]. Scene detail finer than a pixel, and noise the scene's views
// carry (a plenoptic camera's sub-aperture images: correlated over neighbouring pixels), read as
// noise too, but grow from one scale to the next where white noise does not. The estimate at
// scales 1, 2 and 4 (the image's 2^j x 2^j blocks summed) gives the variance v_j; what v_1
// adds to v_0 is scene content, which grows by g = (v_2 - v_1) / (v_1 - v_0) per octave (at
// least 2), so that its part of v_0 is (v_1 - v_0) / (g - 1). 1 when the sigma grows by less
// than 20 % from scale 1 to 2 (white within sampling) or the image is under 8 x 8 pixels.
double white_noise_share(const torch::Tensor& sensor, const torch::Tensor& white);
double white_noise_share(const Phi& phi, const torch::Tensor& sensor);

// How bright a sensor image is: the `quantile` of its pixels, each over its white response (1
// where the scene is white). Pixels whose white response is below a fifth of the mean are left
// out.
double sensor_exposure(const Phi& phi, const torch::Tensor& sensor, double quantile = 0.99);

// Signal-dependent noise: variance = shot * signal + read, signal relative to white. Photon
// shot noise at photons_at_white P gives shot = 1 / P; read noise of e electrons and Gaussian
// noise of sigma give read = (e / P)^2 + sigma^2 (optics/sensor.h).
struct ShotReadEstimate {
  double shot = 0;  // variance per unit of relative signal
  double read = 0;  // variance at no signal
  // The Gaussian sigma of the same variance at `signal`: what a noise-aware net reads
  // (SensorOptions::equivalent_sigma).
  double sigma_at(double signal) const;
};

// Shot and read noise estimated from a sensor image alone, the Poissonian-Gaussian model of Foi
// et al. ("Practical Poissonian-Gaussian noise modeling and fitting for single-image raw-data",
// IEEE TIP 2008) by its simplest fit: the coefficients of estimate_noise_sigma, sorted by the
// signal their pixels see, in `bins` bins of equal counts; per bin the robust variance (the
// median absolute coefficient over 0.6745, squared) at the bin's mean signal; a least-squares
// line through them, shot and read held >= 0. Under Gaussian noise alone shot is about 0 and
// read sigma^2.
ShotReadEstimate estimate_shot_read(const torch::Tensor& sensor, const torch::Tensor& white,
                                    int64_t bins = 12);
ShotReadEstimate estimate_shot_read(const Phi& phi, const torch::Tensor& sensor, int64_t bins = 12);

// What a noise-aware method is told of a sensor image whose noise nobody gives: the Gaussian
// sigma of the same variance at the image's mean signal, from estimate_shot_read (from
// estimate_noise_sigma when the image is too small for the fit).
double estimate_equivalent_sigma(const Phi& phi, const torch::Tensor& sensor);

}  // namespace lfnet::optics
