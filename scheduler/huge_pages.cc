#include "scheduler/huge_pages.h"

#include <gnu/libc-version.h>
#include <unistd.h>

#include <charconv>
#include <cstdlib>
#include <cstring>
#include <fstream>

namespace sf {

namespace {

constexpr std::string_view kTunable = "glibc.malloc.hugetlb";

// How each heap grows and shrinks (see huge_pages.h): 32 MiB at a time, kept until 64 MiB lie
// free at its top, and allocations below 32 MiB from the heap rather than fresh mappings.
constexpr std::string_view kHeapTunables[][2] = {
    {"glibc.malloc.top_pad", "33554432"},
    {"glibc.malloc.mmap_threshold", "33554432"},
    {"glibc.malloc.trim_threshold", "67108864"},
};

// "2.36" -> true for 2.35 and later.
bool has_hugetlb_tunable(std::string_view version) {
  unsigned major = 0, minor = 0;
  const char* const end = version.data() + version.size();
  const auto [dot, e1] = std::from_chars(version.data(), end, major);
  if (e1 != std::errc{} || dot == end || *dot != '.') return false;
  if (std::from_chars(dot + 1, end, minor).ec != std::errc{}) return false;
  return major > 2 || (major == 2 && minor >= 35);
}

}  // namespace

std::optional<std::string> huge_page_tunables(const char* tunables, std::string_view transparent_hugepage,
                                              std::string_view libc_version) {
  const bool huge = transparent_hugepage.find("[madvise]") != std::string_view::npos ||
                    transparent_hugepage.find("[always]") != std::string_view::npos;
  if (!huge && transparent_hugepage.find("[never]") == std::string_view::npos) return std::nullopt;
  if (!has_hugetlb_tunable(libc_version)) return std::nullopt;
  const std::string_view current = tunables ? tunables : "";
  std::string value(current);
  if (current.find(kTunable) != std::string_view::npos) {
    // The user's choice (hugetlb=0 where fresh 2 MiB pages cost more than they save, as on a
    // virtual machine whose host takes freed memory back: bench/README.md, session 39), or this
    // process's own re-execution: the heap tunables still apply, unless they are all set already.
    bool all = true;
    for (const auto& [name, setting] : kHeapTunables) all = all && current.find(name) != std::string_view::npos;
    if (all) return std::nullopt;
  } else {
    if (!value.empty()) value += ':';
    value += kTunable;
    value += huge ? "=1" : "=0";  // 0: nothing to ask for, but it marks the re-execution as done
  }
  for (const auto& [name, setting] : kHeapTunables) {
    if (current.find(name) != std::string_view::npos) continue;  // the user's
    value += ':';
    value += name;
    value += '=';
    value += setting;
  }
  return value;
}

void reexec_with_huge_pages(char** argv) {
  const char* opt_out = std::getenv("SCALEFUSE_HUGE_PAGES");
  if (opt_out && std::strcmp(opt_out, "0") == 0) return;
  std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;  // one line
  if (!std::getline(in, mode)) return;
  const char* before = std::getenv("GLIBC_TUNABLES");
  const std::optional<std::string> value = huge_page_tunables(before, mode, gnu_get_libc_version());
  if (!value) return;
  const std::string saved = before ? before : "";
  if (setenv("GLIBC_TUNABLES", value->c_str(), 1) != 0) return;
  execv("/proc/self/exe", argv);
  // Still here: the exec failed; carry on as started.
  if (before)
    setenv("GLIBC_TUNABLES", saved.c_str(), 1);
  else
    unsetenv("GLIBC_TUNABLES");
}

}  // namespace sf
