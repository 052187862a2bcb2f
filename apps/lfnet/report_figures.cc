#include "report_figures.h"

#include <OpenImageIO/imageio.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "lfnet/core/error.h"
#include "lfnet/core/output.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::app {

namespace {

const cv::Scalar kBlack(0, 0, 0), kGrey(200, 200, 200), kFront(40, 40, 220);

// Colours (BGR) by method, in the order of docs/methods.md.
cv::Scalar method_colour(const std::string& method) {
  static const std::map<std::string, cv::Scalar> colours = {
      {"net", {180, 90, 30}},    {"ae", {60, 160, 60}},   {"cnn", {40, 140, 230}},
      {"dict", {150, 60, 150}},  {"pinv", {60, 60, 200}}, {"adjoint", {120, 120, 120}},
      {"no-parallax", {0, 0, 0}}};
  auto it = colours.find(method);
  return it == colours.end() ? cv::Scalar(100, 100, 100) : it->second;
}

void put_text(cv::Mat& img, const std::string& text, cv::Point at, double scale = 0.45,
              const cv::Scalar& colour = kBlack, int thickness = 1) {
  cv::putText(img, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, colour, thickness, cv::LINE_AA);
}

void write_png(const std::string& path, const cv::Mat& img) {
  fs::create_directories(fs::path(path).parent_path());
  write_file_atomically(path, [&](const std::string& tmp) {
    LFNET_CHECK_AS(IoError, cv::imwrite(tmp, img), "cannot write ", path);
  });
}

// A grey (H, W) float tensor in [0, 1] as an 8-bit image.
cv::Mat to_mat(const torch::Tensor& image) {
  auto t = (image.clamp(0, 1) * 255.0).round().to(torch::kUInt8).contiguous();
  cv::Mat m(static_cast<int>(t.size(0)), static_cast<int>(t.size(1)), CV_8UC1, t.data_ptr());
  return m.clone();
}

std::string format(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), fmt, v);
  return buf;
}

}  // namespace

namespace {
// OpenCV's viridis as a (256, 3) RGB table in [0, 1].
const torch::Tensor& viridis_table() {
  static const torch::Tensor table = [] {
    cv::Mat levels(1, 256, CV_8UC1);
    for (int i = 0; i < 256; ++i) levels.at<uint8_t>(0, i) = static_cast<uint8_t>(i);
    cv::Mat bgr;
    cv::applyColorMap(levels, bgr, cv::COLORMAP_VIRIDIS);
    auto t = torch::empty({256, 3});
    for (int i = 0; i < 256; ++i) {
      const auto c = bgr.at<cv::Vec3b>(0, i);
      for (int k = 0; k < 3; ++k) t[i][k] = static_cast<float>(c[2 - k]) / 255.0f;
    }
    return t;
  }();
  return table;
}
}  // namespace

torch::Tensor viridis(const torch::Tensor& t) {
  auto index = (t.to(torch::kFloat32).clamp(0, 1) * 255).round().to(torch::kLong);
  auto rgb = viridis_table().index({index});  // (S..., 3)
  return rgb.movedim(-1, 0).contiguous();
}

void mark_pareto_front(std::vector<ParetoPoint>& points) {
  std::vector<size_t> order(points.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return points[a].seconds != points[b].seconds ? points[a].seconds < points[b].seconds
                                                  : points[a].psnr_db > points[b].psnr_db;
  });
  double best = -INFINITY;
  for (size_t i : order) {
    points[i].front = points[i].psnr_db > best;
    best = std::max(best, points[i].psnr_db);
  }
}

void plot_pareto(const std::vector<ParetoPoint>& points, const std::string& title,
                 const std::string& path) {
  const int width = 960, height = 600, left = 70, right = 20, top = 50, bottom = 60;
  cv::Mat img(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  put_text(img, title, {left, 25}, 0.6);
  if (points.empty()) {
    write_png(path, img);
    return;
  }
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  for (const auto& p : points) {
    x0 = std::min(x0, std::log10(std::max(p.seconds, 1e-3)));
    x1 = std::max(x1, std::log10(std::max(p.seconds, 1e-3)));
    y0 = std::min(y0, p.psnr_db);
    y1 = std::max(y1, p.psnr_db);
  }
  x0 = std::floor(x0);
  x1 = std::max(std::ceil(x1), x0 + 1);
  y0 = std::floor(y0 - 0.5);
  y1 = std::ceil(y1 + 0.5);
  auto px = [&](double seconds) {
    const double x = std::log10(std::max(seconds, 1e-3));
    return left + static_cast<int>((x - x0) / (x1 - x0) * (width - left - right));
  };
  auto py = [&](double psnr) {
    return height - bottom - static_cast<int>((psnr - y0) / (y1 - y0) * (height - top - bottom));
  };
  // Grid and axes: decades of seconds, whole dB.
  for (double d = x0; d <= x1 + 1e-9; d += 1) {
    const int x = px(std::pow(10.0, d));
    cv::line(img, {x, top}, {x, height - bottom}, kGrey);
    put_text(img, format("%g s", std::pow(10.0, d)), {x - 15, height - bottom + 20});
  }
  const double step = (y1 - y0) > 12 ? 2 : 1;
  for (double y = y0; y <= y1 + 1e-9; y += step) {
    cv::line(img, {left, py(y)}, {width - right, py(y)}, kGrey);
    put_text(img, format("%.0f", y), {left - 30, py(y) + 5});
  }
  put_text(img, "seconds per light field (log scale)", {width / 2 - 120, height - 15}, 0.5);
  put_text(img, "PSNR dB", {5, top - 8}, 0.5);
  // The front, joined in order of time.
  std::vector<const ParetoPoint*> front;
  for (const auto& p : points) {
    if (p.front) front.push_back(&p);
  }
  std::sort(front.begin(), front.end(),
            [](const ParetoPoint* a, const ParetoPoint* b) { return a->seconds < b->seconds; });
  for (size_t i = 1; i < front.size(); ++i) {
    cv::line(img, {px(front[i - 1]->seconds), py(front[i - 1]->psnr_db)},
             {px(front[i]->seconds), py(front[i]->psnr_db)}, kFront, 2, cv::LINE_AA);
  }
  for (const auto& p : points) {
    const cv::Point c(px(p.seconds), py(p.psnr_db));
    cv::circle(img, c, p.front ? 6 : 4, method_colour(p.method), cv::FILLED, cv::LINE_AA);
    if (p.front) cv::circle(img, c, 8, kFront, 1, cv::LINE_AA);
  }
  // Labels: the front's first, then the rest from the best PSNR down, each at the first of four
  // places beside its point that overlaps no label already drawn (or none, where all do).
  const cv::Rect legend(width - right - 165, top, 165, 150);
  std::vector<cv::Rect> taken = {legend};
  std::vector<const ParetoPoint*> order;
  for (const auto& p : points) order.push_back(&p);
  std::stable_sort(order.begin(), order.end(), [](const ParetoPoint* a, const ParetoPoint* b) {
    return a->front != b->front ? a->front : a->psnr_db > b->psnr_db;
  });
  for (const ParetoPoint* p : order) {
    const cv::Point c(px(p->seconds), py(p->psnr_db));
    int baseline = 0;
    const cv::Size size = cv::getTextSize(p->label, cv::FONT_HERSHEY_SIMPLEX, 0.38, 1, &baseline);
    for (const cv::Point at :
         {c + cv::Point(9, -6), c + cv::Point(9, size.height + 6),
          c + cv::Point(-9 - size.width, -6), c + cv::Point(-9 - size.width, size.height + 6)}) {
      const cv::Rect box(at.x - 1, at.y - size.height - 1, size.width + 2,
                         size.height + baseline + 2);
      const bool inside = box.x >= left && box.x + box.width <= width - right && box.y >= top &&
                          box.y + box.height <= height - bottom;
      const bool free = std::none_of(taken.begin(), taken.end(),
                                     [&](const cv::Rect& r) { return (r & box).area() > 0; });
      if (!inside || !free) continue;
      put_text(img, p->label, at, 0.38, p->front ? kFront : cv::Scalar(90, 90, 90));
      taken.push_back(box);
      break;
    }
  }
  // Legend.
  int ly = top + 15;
  for (const auto& m : recon::registered_methods()) {
    cv::circle(img, {width - right - 110, ly - 4}, 5, method_colour(m), cv::FILLED, cv::LINE_AA);
    put_text(img, m, {width - right - 98, ly});
    ly += 18;
  }
  put_text(img, "circled: Pareto front", {width - right - 160, ly + 4}, 0.4, kFront);
  write_png(path, img);
}

void plot_view_heatmap(const std::vector<std::vector<double>>& psnr, const std::string& title,
                       const std::string& path) {
  const int rows = static_cast<int>(psnr.size());
  const int cols = rows ? static_cast<int>(psnr[0].size()) : 0;
  const int cell = 64, top = 40, left = 10;
  cv::Mat img(top + rows * cell + 30, std::max(left * 2 + cols * cell, 360), CV_8UC3,
              cv::Scalar(255, 255, 255));
  put_text(img, title, {left, 25}, 0.5);
  double lo = INFINITY, hi = -INFINITY;
  for (const auto& r : psnr) {
    for (double v : r) {
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  }
  const auto& colours = viridis_table();
  for (int u = 0; u < rows; ++u) {
    for (int v = 0; v < cols; ++v) {
      const double t = hi > lo ? (psnr[u][v] - lo) / (hi - lo) : 0.5;
      const auto c = colours[static_cast<int64_t>(std::round(t * 255))];
      const cv::Rect r(left + v * cell, top + u * cell, cell - 2, cell - 2);
      cv::rectangle(img, r,
                    cv::Scalar(255 * c[2].item<double>(), 255 * c[1].item<double>(),
                               255 * c[0].item<double>()),
                    cv::FILLED);
      put_text(img, format("%.1f", psnr[u][v]), {r.x + 12, r.y + 36}, 0.5,
               t > 0.6 ? kBlack : cv::Scalar(255, 255, 255));
    }
  }
  put_text(img, format("views: rows u, columns v; %.1f", lo) + format(" to %.1f dB", hi),
           {left, top + rows * cell + 20}, 0.42);
  write_png(path, img);
}

void plot_views(const std::vector<LightField>& lfs, const std::vector<std::string>& titles,
                const std::string& path, int64_t crop) {
  LFNET_CHECK(!lfs.empty() && lfs.size() == titles.size(), "plot_views: one title per light field");
  const auto& first = lfs[0];
  const int64_t h = std::min(crop, first.height()), w = std::min(crop, first.width());
  const int64_t y0 = (first.height() - h) / 2, x0 = (first.width() - w) / 2;
  const int64_t cu = first.rows() / 2, cv_ = first.cols() / 2;
  const int64_t epi_scale = 8, epi_h = first.cols() * epi_scale;
  const int gap = 6, title_h = 22;
  const int panel_w = static_cast<int>(w);
  const int total_w = static_cast<int>(lfs.size()) * (panel_w + gap) + gap;
  const int total_h = title_h + static_cast<int>(h) + gap + static_cast<int>(epi_h) + gap +
                      static_cast<int>(h) + gap + 18;
  cv::Mat img(total_h, total_w, CV_8UC3, cv::Scalar(255, 255, 255));
  const torch::Tensor truth = first.data()[0];
  for (size_t i = 0; i < lfs.size(); ++i) {
    const auto& lf = lfs[i];
    LFNET_CHECK(lf.height() == first.height() && lf.width() == first.width() &&
                    lf.rows() == first.rows() && lf.cols() == first.cols(),
                "plot_views: light fields of different shapes");
    const int x = gap + static_cast<int>(i) * (panel_w + gap);
    put_text(img, titles[i], {x, 16}, 0.45);
    const auto data = lf.data()[0];  // (U, V, H, W)
    // Centre view crop.
    cv::Mat view = to_mat(data[cu][cv_].slice(0, y0, y0 + h).slice(1, x0, x0 + w));
    cv::Mat bgr;
    cv::cvtColor(view, bgr, cv::COLOR_GRAY2BGR);
    bgr.copyTo(img(cv::Rect(x, title_h, panel_w, static_cast<int>(h))));
    // Horizontal EPI through the middle row of the crop: views v down, x across, stretched.
    const int64_t row = y0 + h / 2;
    auto epi = data[cu].select(1, row).slice(1, x0, x0 + w);  // (V, w)
    epi = epi.repeat_interleave(epi_scale, 0);
    cv::Mat epi_img;
    cv::cvtColor(to_mat(epi), epi_img, cv::COLOR_GRAY2BGR);
    epi_img.copyTo(
        img(cv::Rect(x, title_h + static_cast<int>(h) + gap, panel_w, static_cast<int>(epi_h))));
    // |error| of the centre view against the truth; 0.1 and above is white.
    auto err =
        (data[cu][cv_] - truth[cu][cv_]).abs().slice(0, y0, y0 + h).slice(1, x0, x0 + w) * 10.0;
    cv::Mat err_img;
    cv::applyColorMap(to_mat(err), err_img, cv::COLORMAP_INFERNO);
    err_img.copyTo(img(cv::Rect(x, title_h + static_cast<int>(h + gap + epi_h + gap), panel_w,
                                static_cast<int>(h))));
  }
  put_text(img,
           "rows: centre view, horizontal EPI (views x columns), |error| x 10 of the centre view",
           {gap, total_h - 5}, 0.4);
  write_png(path, img);
}

void write_parallax_gif(const LightField& lf, const std::string& path, int64_t crop) {
  const int64_t h = std::min(crop, lf.height()), w = std::min(crop, lf.width());
  const int64_t y0 = (lf.height() - h) / 2, x0 = (lf.width() - w) / 2;
  // The angular border, clockwise from the top-left view.
  std::vector<std::pair<int64_t, int64_t>> loop;
  const int64_t U = lf.rows(), V = lf.cols();
  for (int64_t v = 0; v < V; ++v) loop.push_back({0, v});
  for (int64_t u = 1; u < U; ++u) loop.push_back({u, V - 1});
  for (int64_t v = V - 2; v >= 0; --v) loop.push_back({U - 1, v});
  for (int64_t u = U - 2; u >= 1; --u) loop.push_back({u, 0});
  fs::create_directories(fs::path(path).parent_path());
  write_file_atomically(path, [&](const std::string& tmp) {
    auto out = OIIO::ImageOutput::create(tmp);
    LFNET_CHECK_AS(IoError, out != nullptr, "cannot write GIF files: ", OIIO::geterror());
    // GIF frames are RGB: the grey view in all three channels.
    OIIO::ImageSpec spec(static_cast<int>(w), static_cast<int>(h), 3, OIIO::TypeDesc::UINT8);
    const int fps[2] = {8, 1};
    spec.attribute("FramesPerSecond", OIIO::TypeRational, fps);
    spec.attribute("oiio:Movie", 1);
    spec.attribute("gif:LoopCount", 0);
    std::vector<OIIO::ImageSpec> specs(loop.size(), spec);
    LFNET_CHECK_AS(IoError, out->open(tmp, static_cast<int>(specs.size()), specs.data()),
                   "cannot write ", tmp, ": ", out->geterror());
    const auto data = lf.data()[0];
    for (size_t i = 0; i < loop.size(); ++i) {
      if (i > 0) {
        LFNET_CHECK_AS(IoError, out->open(tmp, spec, OIIO::ImageOutput::AppendSubimage),
                       "cannot write ", tmp, ": ", out->geterror());
      }
      auto frame = (data[loop[i].first][loop[i].second]
                        .slice(0, y0, y0 + h)
                        .slice(1, x0, x0 + w)
                        .clamp(0, 1) *
                    255.0)
                       .round()
                       .to(torch::kUInt8)
                       .unsqueeze(-1)
                       .expand({h, w, 3})
                       .contiguous();
      LFNET_CHECK_AS(IoError, out->write_image(OIIO::TypeDesc::UINT8, frame.data_ptr()),
                     "cannot write ", tmp, ": ", out->geterror());
    }
    LFNET_CHECK_AS(IoError, out->close(), "cannot write ", tmp, ": ", out->geterror());
  });
}

}  // namespace lfnet::app
