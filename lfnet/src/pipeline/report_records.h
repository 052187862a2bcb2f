// The records of lfnet report's sections and what its tables read of them: settings, paper
// figures, claims (pipeline/report.cc, report_tables.cc).
#pragma once

#include <nlohmann/json.hpp>

#include <cmath>
#include <string>
#include <vector>

namespace lfnet::pipeline::report {

struct Section {
  std::string name;  // folder name
  nlohmann::json meta;
  std::vector<nlohmann::json> records;
};

// A method's place in the registry's order: tables list methods so.
int method_rank(const std::string& m);

// `v` printed with the printf format `f`.
std::string fmt(const char* f, double v);

// A record's number at `key`, `fallback` where it has none.
double number(const nlohmann::json& r, const char* key, double fallback = NAN);

// The name of a record's Phi ("?" where it has none).
std::string phi_name(const nlohmann::json& r);

// A record's noise: its Gaussian sigma, or with shot and read noise the Gaussian sigma of the
// same variance (docs/acquisition.md).
double noise_level(const nlohmann::json& r);

// The value of a setting of a record, as text: method, phi, n, stride, mode, noise,
// light_field, scale.
std::string setting(const nlohmann::json& r, const std::string& key);

// A numeric setting's text as a number; text that is none ("whole image") sorts last.
double as_number(const std::string& text);

// The settings a record is told apart by, in table order.
extern const std::vector<std::string> kSettings;

// The paper's own test scene, MIT "Dragons and Bunnies" at four apertures (docs/results.md,
// "The paper's scene"): the paper's figures are compared on it alone, at each aperture.
constexpr const char* kPaperScene = "mit_dragons_bunnies";
// The front page's scene: the paper's at the 5 cm aperture.
constexpr const char* kFrontLightField = "mit_dragons_bunnies_5x5_ap5";

// Whether a light field is the paper's scene, at one of its apertures.
bool on_paper_scene(const std::string& light_field);

// The aperture in cm of the paper's scene ("5" of a folder name ending in _ap5), "" for other
// light fields.
std::string aperture(const std::string& light_field);

// "aperture 5 cm" for the paper's scene at that aperture, the light field's name otherwise.
std::string scene_label(const std::string& light_field);

// The sections under `dir` (each folder with a section.json), with their records.
std::vector<Section> read_sections(const std::string& dir);

// Whether a record has every setting a selector names (keys other than settings are ignored).
bool matches(const nlohmann::json& r, const nlohmann::json& selector);

// The paper entry of a section that matches a record: every setting it names must agree.
const nlohmann::json* paper_entry(const Section& s, const nlohmann::json& r);

// The first record of a section that a selector matches.
const nlohmann::json* find_record(const Section& s, const nlohmann::json& selector);

// A claim of the paper about a difference: "a" is better than "b" by paper_db (a number, or
// [low, high]). Ours is psnr(a) - psnr(b) from the section's records.
struct GapClaim {
  std::string section, scene, claim, source;
  double low = NAN, high = NAN, ours = NAN;
};

// The light fields of a section's records: the paper's scene first (by aperture), then others.
std::vector<std::string> light_fields(const Section& s);

// Each claim on each light field of the section: differences on one scene compare across
// scenes, so every scene gets its verdict.
std::vector<GapClaim> gap_claims(const Section& s);

// Reproduced: ours is at least the paper's (lower) gap, less 0.1 dB. A claimed gain that we
// measure as a smaller gain is "direction only"; anything else (a loss, a larger drop) is "no".
constexpr double kGapTolerance = 0.1;
// A figure of the paper is reproduced when ours is at most this far below it.
constexpr double kPsnrTolerance = 0.5;

std::string gap_verdict(const GapClaim& c);

// One paper claim against ours, for the summary at the end.
struct Claim {
  std::string section, scene, setting;
  double paper_psnr = NAN, ours_psnr = NAN, paper_s = NAN, ours_s = NAN;
  std::string source;
};

// A section's records as a Markdown table (RecordTable); a record the paper has a figure for
// is added to `claims`.
std::string markdown_table(const Section& s, std::vector<Claim>& claims);
// net minus no-parallax, dict and pinv for every group of records that differ only in method.
std::string margins(const Section& s);
// The paper's figures beside ours, per aperture of its scene.
std::string paper_numbers(const std::vector<Claim>& claims);
// The paper's claims about differences, judged on every scene measured.
std::string paper_differences(const std::vector<GapClaim>& gaps);

}  // namespace lfnet::pipeline::report
