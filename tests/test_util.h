#pragma once
// Helpers shared by tests: scratch folders and paths to data.
#include <filesystem>
#include <functional>
#include <string>

namespace sf::test {

// A fresh, empty folder under the system temp dir, unique to this process and name; the
// process's folders are removed at its end if all its tests passed.
std::filesystem::path scratch_dir(const std::string& name);
// ../shared/data next to the repository (CI has it beside the clone).
std::filesystem::path shared_data();
// The built command-line program.
std::filesystem::path scalefuse_binary();
// Runs a shell command, returns its exit status (0 = success); output goes to `log` if given.
int run_command(const std::string& command, std::string* log = nullptr);
// Writes `text` to `path`, creating its folders.
void write_text(const std::filesystem::path& path, const std::string& text);
// Expects fn() to throw sf::InputError whose one-line message contains file_part and what.
void expect_input_error(const std::function<void()>& fn, const std::string& file_part, const std::string& what);

}  // namespace sf::test
