// OpenCV's non-local means against lfnet's on pinv reconstructions of noisy sensor images
// (docs/methods.md, "pinv-nlm and OpenCV's non-local means"). Reads the truth's central 5 x 5
// views (grey, Rec. 601 luma) and a reconstruction folder that `lfnet evaluate --method pinv
// --noise S --out DIR` wrote (16-bit views lf_R_C.png), denoises every view with
// cv::fastNlMeansDenoising (one view at a time, on the 16-bit views with the L1 norm) and, with
// --multi, cv::fastNlMeansDenoisingMulti (each view with its row neighbours as frames; OpenCV 4.6
// takes 8-bit views only there; about five times slower), and prints PSNR and seconds for
// several strengths h, given in units of the views' actual noise (measured against the truth:
// an oracle that favours OpenCV). Build and run:
//
//   g++ -O2 -std=c++17 scripts/nlm-opencv.cc -o /tmp/nlm-opencv \
//     $(pkg-config --cflags --libs opencv4)
//   /tmp/nlm-opencv ../shared/data/hci_antinous input_Cam%03d.png 9 DIR [--multi]
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/photo.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace {

cv::Mat grey(const std::string& path) {
  cv::Mat bgr = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (bgr.empty()) throw std::runtime_error("cannot read " + path);
  cv::Mat f;
  bgr.convertTo(f, CV_64F, bgr.depth() == CV_16U ? 1.0 / 65535 : 1.0 / 255);
  if (f.channels() == 1) return f;
  std::vector<cv::Mat> c;
  cv::split(f, c);
  return 0.114 * c[0] + 0.587 * c[1] + 0.299 * c[2];
}

double psnr(const std::vector<cv::Mat>& a, const std::vector<cv::Mat>& b) {
  double se = 0, n = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    cv::Mat d = a[i] - b[i];
    se += d.dot(d);
    n += static_cast<double>(d.total());
  }
  return 10 * std::log10(n / se);
}

std::vector<cv::Mat> as_double(const std::vector<cv::Mat>& views16) {
  std::vector<cv::Mat> out;
  for (const auto& v : views16) {
    cv::Mat f;
    v.convertTo(f, CV_64F, 1.0 / 65535);
    out.push_back(f);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IONBF, 0);
  if (argc != 5 && !(argc == 6 && std::string(argv[5]) == "--multi")) {
    std::fprintf(stderr, "usage: nlm-opencv TRUTH_DIR PATTERN GRID RECON_DIR [--multi]\n");
    return 2;
  }
  const std::string truth_dir = argv[1], pattern = argv[2], recon = argv[4];
  const int grid = std::stoi(argv[3]), first = (grid - 5) / 2;
  std::vector<cv::Mat> truth, noisy16;
  for (int r = 0; r < 5; ++r) {
    for (int c = 0; c < 5; ++c) {
      char name[256];
      std::snprintf(name, sizeof(name), pattern.c_str(), (first + r) * grid + first + c);
      truth.push_back(grey(truth_dir + "/" + name));
      const std::string view =
          recon + "/lf_" + std::to_string(r + 1) + "_" + std::to_string(c + 1) + ".png";
      cv::Mat v = cv::imread(view, cv::IMREAD_UNCHANGED);
      if (v.empty() || v.depth() != CV_16U) throw std::runtime_error("cannot read 16-bit " + view);
      noisy16.push_back(v);
    }
  }
  const auto noisy = as_double(noisy16);
  double se = 0, n = 0;
  for (size_t i = 0; i < noisy.size(); ++i) {
    cv::Mat d = noisy[i] - truth[i];
    se += d.dot(d);
    n += static_cast<double>(d.total());
  }
  const double sigma = std::sqrt(se / n);  // the views' noise, measured: an oracle
  std::printf("input: PSNR %.2f dB, noise %.4f\n", psnr(noisy, truth), sigma);
  std::vector<std::string> modes = {"per view"};
  if (argc == 6) modes.emplace_back("multi (row neighbours)");
  for (const auto& mode : modes) {
    const bool multi = mode[0] == 'm';
    for (double k : {0.5, 0.75, 1.0, 1.5, 2.0}) {
      const float h = static_cast<float>(k * sigma * 65535);
      std::vector<cv::Mat> out(noisy16.size());
      const auto t0 = std::chrono::steady_clock::now();
      for (size_t i = 0; i < noisy16.size(); ++i) {
        if (multi) {
          // The view's row of 5 as frames: window 5 centred where the row allows.
          const int row = static_cast<int>(i) / 5, col = static_cast<int>(i) % 5;
          std::vector<cv::Mat> frames(noisy16.begin() + row * 5, noisy16.begin() + row * 5 + 5);
          std::vector<cv::Mat> ordered(5);
          // Put view `col` in the middle of a window of 5 by reflecting the row.
          for (int j = 0; j < 5; ++j) {
            int src = col - 2 + j;
            if (src < 0) src = -src;
            if (src > 4) src = 8 - src;
            frames[src].convertTo(ordered[j], CV_8U, 1.0 / 257);
          }
          cv::Mat denoised;
          cv::fastNlMeansDenoisingMulti(ordered, denoised, 2, 5, h / 257, 7, 21);
          denoised.convertTo(out[i], CV_16U, 257);
        } else {
          cv::fastNlMeansDenoising(noisy16[i], out[i], std::vector<float>{h}, 7, 21, cv::NORM_L1);
        }
      }
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::printf("%-24s h = %.2f noise: PSNR %.2f dB, %.2f s\n", mode.c_str(), k,
                  psnr(as_double(out), truth), seconds);
    }
  }
  return 0;
}
