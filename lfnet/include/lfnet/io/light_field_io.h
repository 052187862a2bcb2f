// Reading and writing light fields as folders of sub-aperture images, and images for viewing.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "lfnet/core/light_field.h"
#include "lfnet/core/sequence.h"

namespace lfnet::io {

// File naming schemes of sub-aperture folders (see ../shared/data/README.md).
enum class NamingScheme {
  kHciCam,      // input_CamNNN.ext, NNN = rows * row + col, 0-based (HCI benchmark)
  kRowCol,      // lf_R_C.ext, 1-based (Stanford Lytro archive, deepulfcam; lfnet's own writer)
  kTmRowCol,    // TM_RR_CC.ext, 1-based, two digits (Lytro Illum validation set)
  kNameRowCol,  // <name>_RR_CC.ext or <name>-RR-CC.ext: row then column, 0- or 1-based (the
                // lowest index found), any digit count (Lytro exports such as 2067_01_01.png)
  kMitIndex,    // <name>-NN.ext, NN 1-based row-major from the BOTTOM row of views (MIT Synthetic
                // LF Archive: camera Y grows upward), read with its rows reversed
  kCustom,      // a --layout pattern (parse_layout)
};
std::string to_string(NamingScheme scheme);

// One view file of a folder.
struct ViewFile {
  int64_t u = 0;  // 0-based view row
  int64_t v = 0;  // 0-based view column
  std::string path;
};

// What a folder holds: its scheme, grid and one file per view, row-major.
struct FolderLayout {
  NamingScheme scheme = NamingScheme::kRowCol;
  int64_t rows = 0;
  int64_t cols = 0;
  std::vector<ViewFile> views;
};

// A naming pattern for folders no built-in scheme reads (--layout, docs/conventions.md):
// the file name with `{row}` and `{col}` fields (e.g. `view_{row}x{col}.png`), or with one
// `{index}` field and the grid's width, `img{index}.png:cols=9`, numbered row-major unless
// `:col-major` follows. Fields are decimal numbers, 0- or 1-based (the lowest found); `*`
// matches any text. Flips and transposes are --orient's.
struct CustomLayout {
  std::string text;
  std::string pattern;  // the file-name part
  bool index = false;   // one {index} field instead of {row} and {col}
  int64_t cols = 0;     // with index: the width of the grid
  bool col_major = false;
};
// Parses a --layout text; a ConfigError names what is wrong (`what`: the option).
CustomLayout parse_layout(const std::string& text, const std::string& what = "--layout");

// Recognises the naming scheme of a folder and checks the grid is complete. Throws IoError
// naming the folder or the missing file. A non-empty `layout` (parse_layout) replaces the
// recognition.
FolderLayout scan_folder(const std::string& dir, const std::string& layout = "");

// The values a view may hold (radiance relative to white, docs/conventions.md "Value range"):
// within kViewValueSlack of [0, 1] silently, up to kViewValueRefused with a warning (once per
// light field), beyond it refused (an IoError naming the file). Non-finite values are refused.
inline constexpr double kViewValueSlack = 1e-3;
inline constexpr std::pair<double, double> kViewValueRefused = {-1.0, 2.0};

// Whether `dir` holds anything named like a view of a recognised scheme (hidden files aside),
// whether or not the grid is complete: a folder meant as a light field.
bool holds_view_names(const std::string& dir);

// Reads every view of a folder into a light field (C, U, V, H, W) with C = 3 (RGB; alpha
// dropped) or 1 (grey). Views of different sizes or channel counts are an IoError naming the
// file. `threads` <= 0 uses every core.
LightField read_light_field(const std::string& dir, int threads = 0,
                            const std::string& layout = "");

// read_light_field for a command that only reads the views: a folder of grey 16-bit views, whose
// values 16-bit codes hold exactly, is held in codes, half the memory; any other folder (8-bit,
// colour, float) in float32, as read_light_field reads it.
LightFieldViews read_light_field_views(const std::string& dir, int threads = 0,
                                       const std::string& layout = "");

// Reads one image as (C, H, W) float32: integer formats scaled to [0, 1], floats as stored.
torch::Tensor read_image(const std::string& path);

// The most values (W x H x C) an image file may claim before it is read: a corrupt or hostile
// header is refused before lfnet allocates what it claims. 2^30 (4 GiB as float32) by default;
// programs that read untrusted files (or fuzz the readers) may lower it.
void set_image_value_limit(int64_t values);
int64_t image_value_limit();

// Writes a (C, H, W) or (H, W) image in [0, 1]; the extension picks the format. `bits` 8 or
// 16 for integer formats (PNG, TIFF); EXR and float TIFF (bits 32) store float32. The file is
// written to a temporary name and renamed, so a failure leaves no partial file.
void write_image(const std::string& path, const torch::Tensor& image, int bits = 8);

// A (C, H, W) or (H, W) image in [0, 1] as the bytes of an 8-bit PNG file.
std::string encode_png(const torch::Tensor& image);

// An animated GIF of the central `crop` x `crop` pixels that walks the views of a grey light field
// along a loop of the angular border (8 frames per second, looping).
void write_parallax_gif(const LightField& lf, const std::string& path, int64_t crop = 160);

// Options of write_light_field.
struct WriteOptions {
  std::string extension = "png";  // png, tif, exr
  int bits = 16;                  // 8 or 16 for png/tif, 32 for float tif; exr is float
};

// Writes views as DIR/lf_R_C.ext (1-based). The folder must not hold views already.
void write_light_field(const LightFieldViews& lf, const std::string& dir,
                       const WriteOptions& options = {});

// Light-field sequences (docs/video.md): a folder of sub-folders frame_0, frame_1, ...,
// frame_{T-1}, each a light-field folder of any naming scheme read_light_field reads.
// The frame count of a sequence folder: 0 when `dir` holds no frame_0 (a still light field).
// A gap in the numbering (frame_0, frame_2) is an IoError naming the missing frame.
int64_t sequence_frames(const std::string& dir);
// Reads every frame; frames of different shapes are an IoError naming the frame.
LightFieldSequence read_light_field_sequence(const std::string& dir, int threads = 0,
                                             const std::string& layout = "");
// Writes frame t's views as DIR/frame_t/lf_R_C.ext (write_light_field).
void write_light_field_sequence(const LightFieldSequence& seq, const std::string& dir,
                                const WriteOptions& options = {});

// The sub-aperture views tiled into one (C, U * (H + gap) - gap, V * (W + gap) - gap) image.
torch::Tensor grid_image(const LightField& lf, int64_t gap = 2);

// Epipolar-plane images through the central view: horizontal (C, V * scale, W) at spatial row
// `y`, vertical (C, U * scale, H) at column `x` (transposed so it reads left to right).
// Negative y / x take the centre.
torch::Tensor horizontal_epi(const LightFieldViews& lf, int64_t y = -1, int64_t scale = 8);
torch::Tensor vertical_epi(const LightFieldViews& lf, int64_t x = -1, int64_t scale = 8);

// The views averaged over f x f pixel blocks (the rows and columns that do not fill a block
// dropped), a view at a time; `lf` itself (decoded) for f = 1.
LightField downscale_views(const LightFieldViews& lf, int64_t f);

// The light field to tile into a preview grid of at most `max_side` pixels a side: `lf` itself
// when its grid fits, else its views averaged over f x f pixel blocks with the smallest f that
// fits (a 5 x 5 grid of 12-megapixel views is 21,000 pixels wide at full size).
inline constexpr int64_t kPreviewMaxSide = 8192;
LightField preview_light_field(const LightFieldViews& lf, int64_t max_side = kPreviewMaxSide,
                               int64_t gap = 2);

// Writes grid.png (of preview_light_field: at most kPreviewMaxSide pixels a side), epi_h.png and
// epi_v.png (full resolution) into `dir`, for looking at a result.
void write_previews(const LightFieldViews& lf, const std::string& dir);

// PFM by hand: OpenImageIO 2.4 (Debian bookworm) reads PFM but has no PFM writer ("could not
// find a format writer"), and one format is best read and written by one piece of code. GIF
// (write_parallax_gif) goes through OpenImageIO, which writes it.
// Reads a PFM (PF: 3 channels, Pf: 1) as (C, H, W) float32, rows top to bottom.
torch::Tensor read_pfm(const std::string& path);
// Writes a (H, W) or (C, H, W) float tensor as little-endian PFM.
void write_pfm(const std::string& path, const torch::Tensor& image);

}  // namespace lfnet::io
