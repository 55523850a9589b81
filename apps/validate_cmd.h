// `vmap validate`: registered on the CLI by apps/main.cpp (see validate_cmd.cpp).
#pragma once

#include <CLI/CLI.hpp>

namespace vmap::cli {

// Adds the `validate` subcommand to `app`; returns it (true once parsed).
CLI::App* add_validate_command(CLI::App& app);
// Runs it with the parsed options. Throws vmap::Error for bad input.
int run_validate_command();

}  // namespace vmap::cli
