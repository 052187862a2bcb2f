// lfnet models: the model zoo (models/zoo.json, docs/models.md) as a table, or one model's card.
#include <cstdio>
#include <string>

#include "command.h"
#include "lfnet/pipeline/zoo.h"

namespace lfnet::app {

void add_models_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "models", "The model zoo: every shipped model and what it is for, or one model's card");
  auto name = std::make_shared<std::string>();
  cmd->add_option("NAME", *name, "print this model's card (its name in the table)");
  cmd->callback([name] {
    const auto zoo = pipeline::read_zoo();
    const std::string text =
        name->empty() ? pipeline::zoo_table(zoo) : pipeline::zoo_card(zoo, *name);
    std::fputs(text.c_str(), stdout);
  });
}

}  // namespace lfnet::app
