// lfnet sets: the validation and test light-field sets (docs/protocol.md): list their entries,
// or make them as light-field folders that evaluate records as members of their set.
#include <cstdio>
#include <string>
#include <vector>

#include "command.h"
#include "flags.h"
#include "lfnet/pipeline/sets.h"

namespace lfnet::app {

namespace {
struct SetsArgs {
  std::string set, out;
  std::vector<std::string> only;
  bool force = false;
};

void list_set(const SetsArgs& a) {
  const auto set = pipeline::read_set(a.set);
  std::printf("%s (%s): %zu light fields\n", set.name.c_str(), set.role.c_str(),
              set.light_fields.size());
  for (const auto& e : set.light_fields) {
    std::string classes;
    for (const auto& c : e.classes) classes += (classes.empty() ? "" : ", ") + c;
    std::printf("  %-28s %-36s %s\n", e.name.c_str(), classes.c_str(), e.source().c_str());
  }
}
}  // namespace

void add_sets_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "sets", "The validation and test light-field sets: list them, or make their folders");
  cmd->require_subcommand(1);
  auto a = std::make_shared<SetsArgs>();
  auto* list = cmd->add_subcommand("list", "List a set's light fields, their classes and sources");
  input_path(
      list->add_option("SET", a->set, "a set file (configs/sets/validation.json, test.json)"))
      ->required();
  list->callback([a] { list_set(*a); });
  auto* make = cmd->add_subcommand(
      "make", "Write every light field of a set as a folder OUT/NAME (16-bit views, set.json)");
  input_path(
      make->add_option("SET", a->set, "a set file (configs/sets/validation.json, test.json)"))
      ->required();
  output_folder(make->add_option("--out", a->out, "the folder to write the light fields into"))
      ->required();
  make->add_option("--only", a->only, "make only these light fields (by name)");
  add_force_flag(make, a->force);
  make->callback([a] {
    const auto set = pipeline::read_set(a->set);
    pipeline::write_set(set, a->set, a->out, a->only, a->force);
    std::printf("%s (%s): written to %s\n", set.name.c_str(), set.role.c_str(), a->out.c_str());
  });
}

}  // namespace lfnet::app
