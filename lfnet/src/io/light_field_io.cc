#include "lfnet/io/light_field_io.h"

#include <OpenImageIO/imageio.h>
#include <spdlog/spdlog.h>
#include <torch/torch.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <thread>

#include "lfnet/core/error.h"
#include "lfnet/core/file_backed.h"
#include "lfnet/core/file_kind.h"
#include "lfnet/core/output.h"
#include "lfnet/core/parallel.h"
#include "lfnet/core/sequence.h"
#include "lfnet/io/png.h"
#include "lfnet/io/sensor_io.h"

namespace fs = std::filesystem;

namespace lfnet::io {

std::string to_string(NamingScheme scheme) {
  switch (scheme) {
    case NamingScheme::kHciCam:
      return "input_CamNNN (HCI)";
    case NamingScheme::kRowCol:
      return "lf_R_C";
    case NamingScheme::kTmRowCol:
      return "TM_RR_CC";
    case NamingScheme::kNameRowCol:
      return "<name>_RR_CC";
    case NamingScheme::kMitIndex:
      return "<name>-NN (MIT)";
    case NamingScheme::kCustom:
      return "--layout pattern";
  }
  return "unknown";
}

namespace {

// What a path that is not a regular file is, in words: "a folder", "a link that loops", ...
std::string what_is(const fs::path& path) {
  std::error_code ec;
  const auto link = fs::symlink_status(path, ec);
  if (fs::is_symlink(link)) {
    (void)fs::status(path, ec);  // only its error: ELOOP, or a missing target
    if (ec.value() == ELOOP) return "a link that loops";
    if (ec) return "a broken link";
  }
  const auto status = fs::status(path, ec);
  if (fs::is_directory(status)) return "a folder";
  const char* kind = special_file_kind(status);
  return kind != nullptr ? kind : "a special file";
}

const std::regex kHci(R"(^input_Cam(\d+)\.(png|tif|tiff|exr|jpg|jpeg)$)", std::regex::icase);
const std::regex kRowColRe(R"(^lf_(\d+)_(\d+)\.(png|tif|tiff|exr|jpg|jpeg)$)", std::regex::icase);
const std::regex kTm(R"(^TM_(\d+)_(\d+)\.(png|tif|tiff|exr|jpg|jpeg)$)", std::regex::icase);
const std::regex kNameRowColRe(R"(^(.+?)([_-])(\d+)\2(\d+)\.(png|tif|tiff|exr|jpg|jpeg)$)",
                               std::regex::icase);
const std::regex kMit(R"(^(.+)-(\d+)\.(png|tif|tiff|exr|jpg|jpeg)$)", std::regex::icase);

// Side of a square grid holding `count` views, or 0 if not square.
int64_t square_side(int64_t count) {
  auto n = static_cast<int64_t>(std::llround(std::sqrt(static_cast<double>(count))));
  return n * n == count ? n : 0;
}

struct Candidate {
  int64_t a = 0, b = 0;  // index, or (row, col)
  std::string path;
};

FolderLayout layout_from_pairs(NamingScheme scheme, const std::vector<Candidate>& found,
                               const std::string& dir, int64_t base, const std::string& example) {
  FolderLayout layout;
  layout.scheme = scheme;
  std::map<std::pair<int64_t, int64_t>, std::string> grid;
  for (const auto& c : found) {
    LFNET_CHECK_AS(IoError, c.a >= base && c.b >= base, "view file ", c.path,
                   " has an index below ", base);
    auto key = std::make_pair(c.a - base, c.b - base);
    LFNET_CHECK_AS(IoError, grid.emplace(key, c.path).second, "two files name view (", c.a, ", ",
                   c.b, ") in ", dir, ": ", grid[key], " and ", c.path);
    layout.rows = std::max(layout.rows, key.first + 1);
    layout.cols = std::max(layout.cols, key.second + 1);
  }
  for (int64_t u = 0; u < layout.rows; ++u) {
    for (int64_t v = 0; v < layout.cols; ++v) {
      auto it = grid.find({u, v});
      if (it == grid.end()) {
        char name[256];
        const long long row = static_cast<long long>(u) + static_cast<long long>(base);
        const long long col = static_cast<long long>(v) + static_cast<long long>(base);
        std::snprintf(name, sizeof name, example.c_str(), row, col);
        throw IoError("light field folder " + dir + " has a gap in its " +
                      std::to_string(layout.rows) + "x" + std::to_string(layout.cols) +
                      " grid: view file " + name + " is missing");
      }
      layout.views.push_back({u, v, it->second});
    }
  }
  return layout;
}

// Views numbered row-major over a square grid. `rows_up`: the numbering starts at the bottom
// row (a camera whose Y axis points up), so its rows are read in reverse to put u downward.
FolderLayout layout_from_index(NamingScheme scheme, const std::vector<Candidate>& found,
                               const std::string& dir, int64_t base, const std::string& what,
                               bool rows_up = false) {
  int64_t max_index = 0;
  std::map<int64_t, std::string> by_index;
  for (const auto& c : found) {
    LFNET_CHECK_AS(IoError, c.a >= base, "view file ", c.path, " has an index below ", base);
    LFNET_CHECK_AS(IoError, by_index.emplace(c.a - base, c.path).second, "two files name view ",
                   c.a, " in ", dir);
    max_index = std::max(max_index, c.a - base);
  }
  const int64_t n = square_side(max_index + 1);
  LFNET_CHECK_AS(IoError, n > 0, "light field folder ", dir, ": ", what,
                 " views are numbered up to ", max_index + base, ", which is not a square grid");
  FolderLayout layout;
  layout.scheme = scheme;
  layout.rows = layout.cols = n;
  for (int64_t i = 0; i < n * n; ++i) {
    auto it = by_index.find(i);
    LFNET_CHECK_AS(IoError, it != by_index.end(), "light field folder ", dir, " has a gap in its ",
                   n, "x", n, " grid: the ", what, " view numbered ", i + base, " (row ", i / n + 1,
                   ", column ", i % n + 1, ") is missing");
    const int64_t row = rows_up ? n - 1 - i / n : i / n;
    layout.views.push_back({row, i % n, it->second});
  }
  std::sort(layout.views.begin(), layout.views.end(), [](const ViewFile& a, const ViewFile& b) {
    return a.u != b.u ? a.u < b.u : a.v < b.v;
  });
  return layout;
}

}  // namespace

CustomLayout parse_layout(const std::string& text, const std::string& what) {
  CustomLayout l;
  l.text = text;
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t colon; (colon = text.find(':', start)) != std::string::npos; start = colon + 1) {
    parts.push_back(text.substr(start, colon - start));
  }
  parts.push_back(text.substr(start));
  l.pattern = parts[0];
  for (size_t i = 1; i < parts.size(); ++i) {
    if (parts[i] == "col-major") {
      l.col_major = true;
    } else if (parts[i].rfind("cols=", 0) == 0) {
      const std::string n = parts[i].substr(5);
      LFNET_CHECK_AS(
          ConfigError,
          !n.empty() && n.size() <= 3 && n.find_first_not_of("0123456789") == std::string::npos,
          what, " ", text, ": cols= takes the grid's width, 1 to 999");
      l.cols = std::stoll(n);
    } else {
      LFNET_CHECK_AS(ConfigError, false, what, " ", text, ": unknown option '", parts[i],
                     "' (known: cols=N, col-major)");
    }
  }
  const bool row = l.pattern.find("{row}") != std::string::npos;
  const bool col = l.pattern.find("{col}") != std::string::npos;
  l.index = l.pattern.find("{index}") != std::string::npos;
  LFNET_CHECK_AS(ConfigError, l.pattern.find('/') == std::string::npos, what, " ", text,
                 ": a pattern names files inside the folder, without '/'");
  LFNET_CHECK_AS(ConfigError, (row && col && !l.index) || (l.index && !row && !col), what, " ",
                 text,
                 ": give {row} and {col}, or {index} with cols=N (e.g. view_{row}_{col}.png, "
                 "img{index}.png:cols=9)");
  LFNET_CHECK_AS(ConfigError, !l.index || l.cols >= 1, what, " ", text,
                 ": an {index} pattern needs the grid's width, e.g. :cols=9");
  LFNET_CHECK_AS(ConfigError, l.index || (l.cols == 0 && !l.col_major), what, " ", text,
                 ": cols= and col-major apply to {index} patterns");
  return l;
}

namespace {

// The files of `dir` that match a --layout pattern, as (row, col) candidates.
FolderLayout scan_custom(const std::string& dir, const std::vector<std::string>& names,
                         const CustomLayout& l) {
  // The pattern as a regex: literal text escaped, fields as digit groups, '*' as any text.
  std::string re = "^";
  std::vector<std::string> fields;
  for (size_t i = 0; i < l.pattern.size();) {
    bool field = false;
    for (const char* f : {"{row}", "{col}", "{index}"}) {
      if (l.pattern.compare(i, std::strlen(f), f) == 0) {
        re += "(\\d{1,6})";
        fields.emplace_back(f);
        i += std::strlen(f);
        field = true;
        break;
      }
    }
    if (field) continue;
    const char c = l.pattern[i++];
    if (c == '*') {
      re += ".*";
    } else if (std::isalnum(static_cast<unsigned char>(c)) != 0) {
      re += c;
    } else {
      re += std::string("\\") + c;
    }
  }
  re += "$";
  const std::regex matcher(re);
  std::vector<Candidate> found;
  std::smatch m;
  int64_t base = -1;
  for (const auto& name : names) {
    if (!std::regex_match(name, m, matcher)) continue;
    Candidate c;
    c.path = (fs::path(dir) / name).string();
    for (size_t f = 0; f < fields.size(); ++f) {
      const int64_t value = std::stoll(m[f + 1].str());
      if (fields[f] == "{col}") {
        c.b = value;
      } else {
        c.a = value;  // {row} or {index}
      }
    }
    base =
        base < 0 ? std::min(c.a, l.index ? c.a : c.b) : std::min({base, c.a, l.index ? c.a : c.b});
    found.push_back(c);
  }
  LFNET_CHECK_AS(IoError, !found.empty(), "no file in ", dir, " matches --layout ", l.text);
  LFNET_CHECK_AS(IoError, base == 0 || base == 1, "light field folder ", dir,
                 ": its --layout indices start at ", base, "; lfnet reads 0- or 1-based grids");
  if (l.index) {
    int64_t last = 0;
    for (const auto& c : found) last = std::max(last, c.a - base);
    const int64_t count = last + 1;
    LFNET_CHECK_AS(IoError, count % l.cols == 0, "light field folder ", dir,
                   ": views numbered up to ", last + base, " do not fill whole rows of ", l.cols,
                   " (--layout ", l.text, ")");
    const int64_t rows = count / l.cols;
    for (auto& c : found) {
      const int64_t i = c.a - base;
      c.a = (l.col_major ? i % rows : i / l.cols) + base;
      c.b = (l.col_major ? i / rows : i % l.cols) + base;
    }
  }
  std::string example;  // the pattern as printf text for the missing-view message
  for (size_t i = 0; i < l.pattern.size();) {
    if (l.pattern.compare(i, 5, "{row}") == 0 || l.pattern.compare(i, 5, "{col}") == 0) {
      example += "%lld";
      i += 5;
    } else if (l.pattern[i] == '%') {
      example += "%%";
      ++i;
    } else {
      example += l.pattern[i++];
    }
  }
  if (l.index) example = "(row %lld, column %lld of --layout " + l.text + ")";
  if (!l.index && l.pattern.find("{col}") < l.pattern.find("{row}")) {
    // The fields print in pattern order; the message gives (row, col).
    example = "(row %lld, column %lld of --layout " + l.text + ")";
  }
  return layout_from_pairs(NamingScheme::kCustom, found, dir, base, example);
}

// A file name of one of the recognised naming schemes.
bool is_view_name(const std::string& name) {
  return std::regex_match(name, kHci) || std::regex_match(name, kRowColRe) ||
         std::regex_match(name, kTm) || std::regex_match(name, kNameRowColRe) ||
         std::regex_match(name, kMit);
}

}  // namespace

FolderLayout scan_folder(const std::string& dir, const std::string& layout) {
  std::error_code ec;
  LFNET_CHECK_AS(IoError, fs::is_directory(dir, ec), "light field folder ", dir,
                 " does not exist or is not a folder");
  // Hidden files (".DS_Store", the "._lf_1_1.png" resource forks macOS leaves on other file
  // systems) are no views. A view name that is not a regular file (a folder) is an error
  // naming it, not a view gone missing.
  std::vector<std::string> names, not_files;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name[0] == '.') continue;
    std::error_code kind_ec;
    (entry.is_regular_file(kind_ec) ? names : not_files).push_back(name);
  }
  LFNET_CHECK_AS(IoError, !ec, "cannot list ", dir, ": ", ec.message());
  std::sort(names.begin(), names.end());
  if (!layout.empty()) {
    try {
      return scan_custom(dir, names, parse_layout(layout));
    } catch (const IoError& e) {
      if (not_files.empty()) throw;
      throw IoError(std::string(e.what()) + " (" + (fs::path(dir) / not_files.front()).string() +
                    " is not a regular file: a view is an image file)");
    }
  }
  for (const auto& name : not_files) {
    const auto path = fs::path(dir) / name;
    LFNET_CHECK_AS(IoError, !is_view_name(name), "view ", path.string(),
                   " is not a regular file but ", what_is(path), ": a view is an image file");
  }

  std::map<NamingScheme, std::vector<Candidate>> found;
  std::string generic_prefix;  // <name>_ of <name>_RR_CC, which every such file must share
  std::smatch m;
  auto index = [&](const std::string& digits, const std::string& name) {
    // A view index is small; more digits than that is a foreign file, not a grid of 10^18.
    LFNET_CHECK_AS(IoError, digits.size() <= 6, "view file ", (fs::path(dir) / name).string(),
                   " has an index of ", digits.size(), " digits; view indices have at most 6");
    return static_cast<int64_t>(std::stoll(digits));
  };
  for (const auto& name : names) {
    const std::string path = (fs::path(dir) / name).string();
    if (std::regex_match(name, m, kHci)) {
      found[NamingScheme::kHciCam].push_back({index(m[1], name), 0, path});
    } else if (std::regex_match(name, m, kRowColRe)) {
      found[NamingScheme::kRowCol].push_back({index(m[1], name), index(m[2], name), path});
    } else if (std::regex_match(name, m, kTm)) {
      found[NamingScheme::kTmRowCol].push_back({index(m[1], name), index(m[2], name), path});
    } else if (std::regex_match(name, m, kNameRowColRe)) {
      const std::string prefix = m[1].str() + m[2].str();
      if (generic_prefix.empty()) generic_prefix = prefix;
      LFNET_CHECK_AS(IoError, prefix == generic_prefix, "light field folder ", dir,
                     " holds views of two light fields (", generic_prefix, "RR_CC and ", prefix,
                     "RR_CC): keep one light field per folder");
      found[NamingScheme::kNameRowCol].push_back({index(m[3], name), index(m[4], name), path});
    } else if (std::regex_match(name, m, kMit)) {
      found[NamingScheme::kMitIndex].push_back({index(m[2], name), 0, path});
    }
  }
  if (found.empty()) {
    throw IoError(
        "no light field views found in " + dir +
        ": expected input_CamNNN.png, lf_R_C.png, TM_RR_CC.png, <name>_RR_CC.png (or -RR-CC) or "
        "<name>-NN.png files");
  }
  if (found.size() > 1) {
    std::string schemes;  // each with its first file, so the odd one out can be found
    for (const auto& [scheme, files] : found) {
      schemes += (schemes.empty() ? "" : ", ") + to_string(scheme) + " such as " +
                 fs::path(files.front().path).filename().string();
    }
    throw IoError("light field folder " + dir + " mixes naming schemes (" + schemes +
                  "): keep one light field per folder");
  }
  auto& [scheme, files] = *found.begin();
  switch (scheme) {
    case NamingScheme::kCustom:  // a --layout pattern returned above
      break;
    case NamingScheme::kHciCam:
      return layout_from_index(scheme, files, dir, 0, "input_Cam");
    // The MIT archive's README places file 01 at camera Y = -2.5 cm and 21 at +2.5 cm with Y
    // growing upward: its first row of files is the bottom row of views.
    case NamingScheme::kMitIndex:
      return layout_from_index(scheme, files, dir, 1, "<name>-NN", /*rows_up=*/true);
    case NamingScheme::kRowCol:
      return layout_from_pairs(scheme, files, dir, 1, "lf_%lld_%lld.png");
    case NamingScheme::kTmRowCol:
      return layout_from_pairs(scheme, files, dir, 1, "TM_%02lld_%02lld.png");
    case NamingScheme::kNameRowCol: {
      int64_t base = files.front().a;
      for (const auto& c : files) base = std::min({base, c.a, c.b});
      LFNET_CHECK_AS(IoError, base == 0 || base == 1, "light field folder ", dir, ": ",
                     generic_prefix, "RR_CC views start at row or column ", base,
                     "; lfnet reads 0- or 1-based grids");
      std::string literal;  // the prefix as printf text: a file name may hold '%'
      for (char c : generic_prefix) literal += c == '%' ? std::string("%%") : std::string(1, c);
      return layout_from_pairs(scheme, files, dir, base,
                               literal + "%02lld" + generic_prefix.back() + "%02lld.png");
    }
  }
  throw IoError("unhandled naming scheme");
}

namespace {

// One warning per light field whose values leave [0, 1] by more than rounding (an HDR highlight,
// a float pipeline's negative noise), naming the first such view; `range` holds each view's
// (min, max).
void warn_view_range(const std::vector<std::pair<double, double>>& range,
                     const FolderLayout& layout) {
  double min = 0, max = 1;
  std::string first;
  for (size_t i = 0; i < range.size(); ++i) {
    const auto [a, b] = range[i];
    if ((a < -kViewValueSlack || b > 1 + kViewValueSlack) && first.empty()) {
      first = layout.views[i].path;
    }
    min = std::min(min, a);
    max = std::max(max, b);
  }
  if (first.empty()) return;
  spdlog::warn(
      "light field views hold values from {:.4g} to {:.4g} (first: {}); lfnet reads radiance in "
      "[0, 1], clamps what it writes to it and scores against it",
      min, max, first);
}

std::string size_text(const torch::Tensor& chw) {
  return std::to_string(chw.size(2)) + "x" + std::to_string(chw.size(1)) + " with " +
         std::to_string(chw.size(0)) + " channels";
}

}  // namespace

bool holds_view_names(const std::string& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.empty() || name[0] == '.') continue;
    if (is_view_name(name)) return true;
  }
  return false;
}

namespace {

// A view is radiance relative to white, in [0, 1]; a float file far outside that holds another
// unit (docs/conventions.md, "Value range").
void check_view_values(const std::string& path, double min, double max) {
  LFNET_CHECK_AS(IoError, min >= kViewValueRefused.first && max <= kViewValueRefused.second,
                 "image ", path, " holds values from ", min, " to ", max,
                 "; lfnet reads views as radiance in [0, 1] (white = 1): scale the files (e.g. "
                 "divide by their largest value)");
}

}  // namespace

torch::Tensor read_image(const std::string& path) {
  auto chw = read_image_channels(path);
  const int64_t nc = chw.size(0);
  // Alpha is dropped: grey+alpha -> grey, RGBA -> RGB.
  int64_t keep = nc;
  if (nc == 2) keep = 1;
  if (nc >= 4) keep = 3;
  LFNET_CHECK_AS(IoError, keep == 1 || keep == 3, "image ", path, " has ", nc,
                 " channels; lfnet reads grey, grey+alpha, RGB and RGBA");
  chw = chw.slice(0, 0, keep).contiguous();
  // Non-finite values were refused by read_image_channels.
  const auto [lo, hi] = torch::aminmax(chw);
  check_view_values(path, lo.item<double>(), hi.item<double>());
  return chw;
}

namespace {
// View `path`, which must have the size and channels of `first` (read from `first_path`).
torch::Tensor read_view_like(const std::string& path, const torch::Tensor& first,
                             const std::string& first_path) {
  auto image = read_image(path);
  if (image.sizes() != first.sizes()) {
    throw IoError("view " + path + " is " + size_text(image) + ", but " + first_path + " is " +
                  size_text(first) + ": every view must have the same size and channels");
  }
  return image;
}
}  // namespace

LightField read_light_field(const std::string& dir, int threads, const std::string& naming) {
  const FolderLayout layout = scan_folder(dir, naming);
  const int64_t n = static_cast<int64_t>(layout.views.size());
  // The first view gives the size; every view is then read straight into its place, so the
  // light field is held once (not as a list of views and a stacked copy).
  const auto first = read_image(layout.views[0].path);
  const int64_t c = first.size(0), h = first.size(1), w = first.size(2);
  auto data = torch::empty({c, layout.rows, layout.cols, h, w}, torch::kFloat32);
  std::vector<std::pair<double, double>> range(static_cast<size_t>(n));
  auto slot = [&](int64_t i) {  // view i's (C, H, W) in place
    const auto& view = layout.views[static_cast<size_t>(i)];
    return data.index({torch::indexing::Slice(), view.u, view.v});
  };
  auto place = [&](int64_t i, const torch::Tensor& image) {
    const auto [lo, hi] = torch::aminmax(image);
    range[static_cast<size_t>(i)] = {lo.item<double>(), hi.item<double>()};
    slot(i).copy_(image);
  };
  place(0, first);
  parallel_chunks(
      n - 1, 1,
      [&](int64_t begin, int64_t end) {
        for (int64_t i = begin + 1; i < end + 1; ++i) {
          const auto& path = layout.views[static_cast<size_t>(i)].path;
          // A grey file of the first view's size is decoded straight into its place.
          if (c == 1) {
            if (auto r = read_grey_image_into(path, slot(i)[0])) {
              check_view_values(path, r->first, r->second);
              range[static_cast<size_t>(i)] = *r;
              continue;
            }
          }
          place(i, read_view_like(path, first, layout.views[0].path));
        }
      },
      threads > 0 ? threads : static_cast<int>(std::thread::hardware_concurrency()));
  warn_view_range(range, layout);
  return LightField(data);
}

LightFieldViews read_light_field_views(const std::string& dir, int threads,
                                       const std::string& naming) {
  const FolderLayout layout = scan_folder(dir, naming);
  const int64_t n = static_cast<int64_t>(layout.views.size());
  {
    // Only grey 16-bit files can be codes: the header says, before anything is decoded.
    auto input = OIIO::ImageInput::open(layout.views[0].path);
    if (!input || input->spec().nchannels != 1 || input->spec().format != OIIO::TypeDesc::UINT16) {
      return LightFieldViews(read_light_field(dir, threads, naming));
    }
  }
  const auto first = read_image(layout.views[0].path);
  const int64_t h = first.size(1), w = first.size(2);
  auto codes = file_backed_empty({1, layout.rows, layout.cols, h, w}, torch::kInt16);  // when large
  std::vector<std::pair<double, double>> range(static_cast<size_t>(n));
  std::atomic<bool> exact{true};
  auto place = [&](int64_t i, const torch::Tensor& image) {
    const auto [lo, hi] = torch::aminmax(image);
    range[static_cast<size_t>(i)] = {lo.item<double>(), hi.item<double>()};
    auto code = encode_codes(image);
    if (!torch::equal(decode_codes(code), image)) exact = false;  // not 16-bit values
    const auto& view = layout.views[static_cast<size_t>(i)];
    auto place = codes.index({torch::indexing::Slice(), view.u, view.v});
    place.copy_(code);
    page_out(place);  // a file-backed light field holds no view in memory once it is placed
  };
  place(0, first);
  parallel_chunks(
      n - 1, 1,
      [&](int64_t begin, int64_t end) {
        for (int64_t i = begin + 1; i < end + 1 && exact; ++i) {
          const auto& path = layout.views[static_cast<size_t>(i)].path;
          place(i, read_view_like(path, first, layout.views[0].path));
        }
      },
      threads > 0 ? threads : static_cast<int>(std::thread::hardware_concurrency()));
  if (!exact) return LightFieldViews(read_light_field(dir, threads, naming));
  warn_view_range(range, layout);
  return LightFieldViews(codes);
}

namespace {
bool is_png(const std::string& path) {
  auto ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".png";
}

// A (C, H, W) image in [0, 1] as (H, W, C) 8- or 16-bit samples, rounded as OpenImageIO does
// (x * max + 0.5, truncated; NaN as 0). 16-bit samples are held in int16 (their bits).
torch::Tensor integer_samples(const torch::Tensor& chw, int bits) {
  const double max = bits == 16 ? 65535.0 : 255.0;
  // One float32 copy, changed in place (a 12-megapixel image: 48 MB, not four such).
  auto scaled = chw.to(torch::kFloat32, /*non_blocking=*/false, /*copy=*/true);
  scaled.nan_to_num_(0.0, 1.0, 0.0).clamp_(0, 1).mul_(max).add_(0.5);
  scaled = scaled.permute({1, 2, 0});
  return bits == 16 ? scaled.to(torch::kInt32).to(torch::kInt16).contiguous()
                    : scaled.to(torch::kUInt8).contiguous();
}

// (H, W, C) samples of `bits` (integer_samples, or 16-bit codes) as a PNG file, atomically.
void write_png(const std::string& path, const torch::Tensor& hwc, int bits) {
  write_bytes_file(path,
                   encode_png_samples(hwc.data_ptr(), hwc.size(0), hwc.size(1), hwc.size(2), bits));
}
}  // namespace

void write_image(const std::string& path, const torch::Tensor& image, int bits) {
  LFNET_CHECK(image.dim() == 2 || image.dim() == 3, "write_image takes (H, W) or (C, H, W)");
  auto chw = image.dim() == 2 ? image.unsqueeze(0) : image;
  const int64_t c = chw.size(0), h = chw.size(1), w = chw.size(2);
  const std::string ext = fs::path(path).extension().string();
  const bool is_float = ext == ".exr" || ext == ".pfm" || bits == 32;
  if (!is_float && is_png(path) && c <= 4) {
    write_png(path, integer_samples(chw, bits == 16 ? 16 : 8), bits == 16 ? 16 : 8);
    return;
  }
  auto hwc = chw.to(torch::kFloat32).permute({1, 2, 0}).contiguous();
  if (!is_float) hwc = hwc.clamp(0, 1);
  OIIO::TypeDesc type = is_float ? OIIO::TypeDesc::FLOAT
                                 : (bits == 16 ? OIIO::TypeDesc::UINT16 : OIIO::TypeDesc::UINT8);
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw IoError("cannot write " + path + ": unknown image format " + ext);
  OIIO::ImageSpec spec(static_cast<int>(w), static_cast<int>(h), static_cast<int>(c), type);
  spec.attribute("oiio:UnassociatedAlpha", 1);
  write_file_atomically(path, [&](const std::string& tmp) {
    const bool ok = out->open(tmp, spec) &&
                    out->write_image(OIIO::TypeDesc::FLOAT, hwc.data_ptr<float>()) && out->close();
    if (!ok) throw IoError("cannot write " + path + ": " + out->geterror());
  });
}

namespace {
// Writes 16-bit values k (LightFieldViews::view_bits: (C, H, W), the bits of uint16) to a PNG or
// TIFF file as they are: no float32 copy, no conversion.
void write_bits16(const std::string& path, const torch::Tensor& bits) {
  const int64_t c = bits.size(0), h = bits.size(1), w = bits.size(2);
  auto hwc = bits.permute({1, 2, 0}).contiguous();
  if (is_png(path) && c <= 4) {
    write_png(path, hwc, 16);
    return;
  }
  auto out = OIIO::ImageOutput::create(path);
  LFNET_CHECK_AS(IoError, out, "cannot write ", path, ": ", OIIO::geterror());
  OIIO::ImageSpec spec(static_cast<int>(w), static_cast<int>(h), static_cast<int>(c),
                       OIIO::TypeDesc::UINT16);
  write_file_atomically(path, [&](const std::string& tmp) {
    const bool ok = out->open(tmp, spec) &&
                    out->write_image(OIIO::TypeDesc::UINT16, hwc.data_ptr<int16_t>()) &&
                    out->close();
    if (!ok) throw IoError("cannot write " + path + ": " + out->geterror());
  });
}
}  // namespace

std::string encode_png(const torch::Tensor& image) {
  LFNET_CHECK(image.dim() == 2 || image.dim() == 3, "encode_png takes (H, W) or (C, H, W)");
  const auto hwc = integer_samples(image.dim() == 2 ? image.unsqueeze(0) : image, 8);
  return encode_png_samples(hwc.data_ptr(), hwc.size(0), hwc.size(1), hwc.size(2), 8);
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

void write_light_field(const LightFieldViews& lf, const std::string& dir,
                       const WriteOptions& options) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  LFNET_CHECK_AS(IoError, !ec && fs::is_directory(dir), "cannot create folder ", dir, ": ",
                 ec.message());
  // One encode per view, on LibTorch's thread count (the first error is passed on).
  const int64_t cols = lf.cols();
  parallel_chunks(lf.rows() * cols, 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const int64_t u = i / cols, v = i % cols;
      auto name =
          "lf_" + std::to_string(u + 1) + "_" + std::to_string(v + 1) + "." + options.extension;
      const auto path = (fs::path(dir) / name).string();
      // 16-bit codes go to 16-bit files as they are.
      if (lf.coded() && options.bits == 16 &&
          (options.extension == "png" || options.extension == "tif")) {
        write_bits16(path, lf.view_bits(u, v));
      } else {
        write_image(path, lf.view(u, v), options.bits);
      }
    }
  });
}

int64_t sequence_frames(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(fs::path(dir) / "frame_0", ec)) return 0;
  static const std::regex kFrame(R"(frame_(0|[1-9][0-9]{0,5}))");
  int64_t count = 0, last = -1;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    std::smatch m;
    const auto name = entry.path().filename().string();
    if (!entry.is_directory() || !std::regex_match(name, m, kFrame)) continue;
    ++count;
    last = std::max<int64_t>(last, std::stoll(m[1]));
  }
  LFNET_CHECK_AS(IoError, !ec, "cannot list ", dir, ": ", ec.message());
  if (count != last + 1) {
    for (int64_t t = 0; t <= last; ++t) {
      LFNET_CHECK_AS(IoError, fs::is_directory(sequence_frame_dir(dir, t)), dir,
                     " is a sequence of frames up to frame_", last, " but has no frame_", t);
    }
  }
  return count;
}

LightFieldSequence read_light_field_sequence(const std::string& dir, int threads,
                                             const std::string& layout) {
  const int64_t frames = sequence_frames(dir);
  LFNET_CHECK_AS(IoError, frames > 0, dir, " is not a light-field sequence (no frame_0 folder)");
  std::vector<LightField> out;
  for (int64_t t = 0; t < frames; ++t) {
    const auto frame = sequence_frame_dir(dir, t);
    out.push_back(read_light_field(frame, threads, layout));
    LFNET_CHECK_AS(IoError, out.back().data().sizes() == out.front().data().sizes(), frame, " is ",
                   out.back().shape_string(), " but frame_0 is ", out.front().shape_string());
  }
  return LightFieldSequence(out);
}

void write_light_field_sequence(const LightFieldSequence& seq, const std::string& dir,
                                const WriteOptions& options) {
  for (int64_t t = 0; t < seq.frames(); ++t) {
    write_light_field(seq.frame(t), sequence_frame_dir(dir, t), options);
  }
}

namespace {
// The cell of view (u, v) in a grid of h x w views `gap` pixels apart, whose rows run along
// dimension `row_dim` and columns along the next.
torch::Tensor grid_cell(const torch::Tensor& grid, int64_t row_dim, int64_t u, int64_t v, int64_t h,
                        int64_t w, int64_t gap) {
  return grid.slice(row_dim, u * (h + gap), u * (h + gap) + h)
      .slice(row_dim + 1, v * (w + gap), v * (w + gap) + w);
}

// A (C, H, W) view's area averages of f x f pixels (the last rows and columns that do not fill a
// block dropped).
torch::Tensor downscale_view(const torch::Tensor& view, int64_t f) {
  return f == 1 ? view : torch::avg_pool2d(view.unsqueeze(1), {f, f}, {f, f}).squeeze(1);
}
}  // namespace

torch::Tensor grid_image(const LightField& lf, int64_t gap) {
  const int64_t c = lf.channels(), u = lf.rows(), v = lf.cols(), h = lf.height(), w = lf.width();
  auto out = torch::ones({c, u * (h + gap) - gap, v * (w + gap) - gap});
  for (int64_t i = 0; i < u; ++i) {
    for (int64_t j = 0; j < v; ++j) grid_cell(out, 1, i, j, h, w, gap).copy_(lf.view(i, j));
  }
  return out;
}

torch::Tensor horizontal_epi(const LightFieldViews& lf, int64_t y, int64_t scale) {
  if (y < 0) y = lf.height() / 2;
  LFNET_CHECK(y < lf.height(), "EPI row ", y, " outside the image");
  // (C, V, W) at the central view row, each view repeated `scale` times.
  std::vector<torch::Tensor> rows;
  for (int64_t v = 0; v < lf.cols(); ++v) rows.push_back(lf.view(lf.rows() / 2, v).select(1, y));
  return torch::stack(rows, 1).repeat_interleave(scale, 1);
}

torch::Tensor vertical_epi(const LightFieldViews& lf, int64_t x, int64_t scale) {
  if (x < 0) x = lf.width() / 2;
  LFNET_CHECK(x < lf.width(), "EPI column ", x, " outside the image");
  // (C, U, H) at the central view column.
  std::vector<torch::Tensor> cols;
  for (int64_t u = 0; u < lf.rows(); ++u) cols.push_back(lf.view(u, lf.cols() / 2).select(2, x));
  return torch::stack(cols, 1).repeat_interleave(scale, 1);
}

LightField downscale_views(const LightFieldViews& lf, int64_t f) {
  LFNET_CHECK(f >= 1 && f <= lf.height() && f <= lf.width(), "downscale_views: factor ", f,
              " for views of ", lf.height(), "x", lf.width());
  if (f == 1) return lf.decode();
  // A view at a time.
  auto small = torch::empty({lf.channels(), lf.rows(), lf.cols(), lf.height() / f, lf.width() / f});
  for (int64_t u = 0; u < lf.rows(); ++u) {
    for (int64_t v = 0; v < lf.cols(); ++v) {
      small.select(axis::kU, u).select(axis::kU, v).copy_(downscale_view(lf.view(u, v), f));
    }
  }
  return LightField(small);
}

namespace {
// preview_light_field's factor.
int64_t preview_factor(const LightFieldViews& lf, int64_t max_side, int64_t gap) {
  LFNET_CHECK(max_side >= 1, "preview_light_field: max_side must be positive");
  const int64_t u = lf.rows(), v = lf.cols(), h = lf.height(), w = lf.width();
  int64_t f = 1;
  while ((u * (h / f + gap) - gap > max_side || v * (w / f + gap) - gap > max_side) &&
         f < std::min(h, w)) {
    ++f;
  }
  return f;
}
}  // namespace

LightField preview_light_field(const LightFieldViews& lf, int64_t max_side, int64_t gap) {
  return downscale_views(lf, preview_factor(lf, max_side, gap));
}

void write_previews(const LightFieldViews& lf, const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  // grid_image(preview_light_field(lf)) in 8-bit samples, placed a view at a time on LibTorch's
  // thread count: no float copy of the whole light field or of the grid is made.
  constexpr int64_t kGap = 2;
  const int64_t f = preview_factor(lf, kPreviewMaxSide, kGap);
  const int64_t h = lf.height() / f, w = lf.width() / f, cols = lf.cols();
  auto grid = torch::full({lf.rows() * (h + kGap) - kGap, cols * (w + kGap) - kGap, lf.channels()},
                          255, torch::kUInt8);
  parallel_chunks(lf.rows() * cols, 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const int64_t u = i / cols, v = i % cols;
      grid_cell(grid, 0, u, v, h, w, kGap)
          .copy_(integer_samples(downscale_view(lf.view(u, v), f), 8));
    }
  });
  write_png((fs::path(dir) / "grid.png").string(), grid, 8);
  write_image((fs::path(dir) / "epi_h.png").string(), horizontal_epi(lf));
  write_image((fs::path(dir) / "epi_v.png").string(), vertical_epi(lf));
}

torch::Tensor read_pfm(const std::string& path) {
  check_regular_input(path);
  std::ifstream in(path, std::ios::binary);
  LFNET_CHECK_AS(IoError, in, "cannot open PFM file ", path);
  std::string magic;
  int64_t w = 0, h = 0;
  double scale = 0;
  in >> magic >> w >> h >> scale;
  LFNET_CHECK_AS(IoError, in && (magic == "PF" || magic == "Pf") && w > 0 && h > 0 && scale != 0,
                 "PFM file ", path, " has a malformed header");
  in.get();  // the single whitespace after the scale
  const int64_t c = magic == "PF" ? 3 : 1;
  // Check the header against the file's size before allocating what it claims.
  const auto header_end = static_cast<int64_t>(in.tellg());
  std::error_code ec;
  const auto file_size = static_cast<int64_t>(fs::file_size(path, ec));
  LFNET_CHECK_AS(IoError,
                 !ec && w <= file_size && h <= file_size && w * h * c * 4 <= file_size - header_end,
                 "PFM file ", path, " is truncated: its header claims ", w, "x", h, "x", c,
                 " floats, more than the file holds");
  auto data = torch::empty({h, w, c}, torch::kFloat32);
  const auto bytes = static_cast<std::streamsize>(h * w * c * sizeof(float));
  in.read(reinterpret_cast<char*>(data.data_ptr<float>()), bytes);
  LFNET_CHECK_AS(IoError, in.gcount() == bytes, "PFM file ", path, " is truncated: expected ",
                 bytes, " bytes of pixels, found ", in.gcount());
  if (scale > 0) {  // big-endian data
    auto* p = reinterpret_cast<uint32_t*>(data.data_ptr<float>());
    for (int64_t i = 0; i < h * w * c; ++i) p[i] = __builtin_bswap32(p[i]);
  }
  // PFM stores rows bottom to top.
  return data.flip({0}).permute({2, 0, 1}).contiguous();
}

void write_pfm(const std::string& path, const torch::Tensor& image) {
  auto chw = image.dim() == 2 ? image.unsqueeze(0) : image;
  LFNET_CHECK(chw.dim() == 3 && (chw.size(0) == 1 || chw.size(0) == 3),
              "PFM holds 1 or 3 channels");
  auto hwc = chw.to(torch::kFloat32).permute({1, 2, 0}).flip({0}).contiguous();
  std::string bytes = std::string(chw.size(0) == 3 ? "PF" : "Pf") + "\n" +
                      std::to_string(chw.size(2)) + " " + std::to_string(chw.size(1)) + "\n-1.0\n";
  bytes.append(reinterpret_cast<const char*>(hwc.data_ptr<float>()),
               static_cast<size_t>(hwc.numel()) * sizeof(float));
  write_bytes_file(path, bytes);
}

}  // namespace lfnet::io
