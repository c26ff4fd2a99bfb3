#include "scheduler/huge_pages.h"

#include <gnu/libc-version.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <charconv>
#include <cstdlib>
#include <cstring>
#include <filesystem>
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

// THP mode `always`: huge pages come unasked, whatever glibc.malloc.hugetlb says.
bool gives_unasked(std::string_view transparent_hugepage) {
  return transparent_hugepage.find("[always]") != std::string_view::npos;
}

bool gives_huge_pages(std::string_view transparent_hugepage) {
  return transparent_hugepage.find("[madvise]") != std::string_view::npos || gives_unasked(transparent_hugepage);
}

// Whether any virtio-balloon device of this machine reports free pages to its host.
// It runs before main's try block: the iteration uses error codes throughout (a range-for's
// increment would throw).
bool balloon_reports_free_pages() {
  std::error_code ec;
  std::filesystem::directory_iterator it("/sys/bus/virtio/drivers/virtio_balloon", ec), end;
  for (; !ec && it != end; it.increment(ec)) {
    std::ifstream in(it->path() / "features");
    std::string features;
    if (in && std::getline(in, features) && reports_free_pages(features)) return true;
  }
  return false;
}

// The value of glibc.malloc.hugetlb the user set in `tunables`, or nullopt.
std::optional<std::string_view> users_hugetlb(const char* tunables) {
  if (!tunables) return std::nullopt;
  const std::string_view t(tunables);
  const std::size_t at = t.find(kTunable);
  if (at == std::string_view::npos) return std::nullopt;
  std::string_view v = t.substr(at + kTunable.size());
  if (v.empty() || v.front() != '=') return std::string_view{};
  v.remove_prefix(1);
  return v.substr(0, v.find(':'));
}

}  // namespace

bool reports_free_pages(std::string_view balloon_features) {
  return balloon_features.size() > 5 && balloon_features[5] == '1';
}

bool disables_transparent_huge_pages(const char* tunables, std::string_view transparent_hugepage,
                                     bool host_reports_free_pages) {
  if (!gives_unasked(transparent_hugepage)) return false;
  const std::optional<std::string_view> user = users_hugetlb(tunables);
  return user ? *user == "0" : host_reports_free_pages;
}

std::optional<std::string> huge_page_tunables(const char* tunables, std::string_view transparent_hugepage,
                                              std::string_view libc_version, bool host_reports_free_pages) {
  const bool huge = gives_huge_pages(transparent_hugepage);
  if (!huge && transparent_hugepage.find("[never]") == std::string_view::npos) return std::nullopt;
  if (!has_hugetlb_tunable(libc_version)) return std::nullopt;
  const std::string_view current = tunables ? tunables : "";
  std::string value(current);
  if (users_hugetlb(tunables)) {
    // The user's choice (hugetlb=1 for a job of many GB on a machine whose balloon reports free
    // pages, huge_pages.h), or this process's own re-execution: the heap tunables still apply,
    // unless they are all set already.
    bool all = true;
    for (const auto& [name, setting] : kHeapTunables) all = all && current.find(name) != std::string_view::npos;
    if (all) return std::nullopt;
  } else {
    if (!value.empty()) value += ':';
    value += kTunable;
    // 0 where there is nothing to ask for (it still marks the re-execution as done) or where
    // fresh huge pages are the host's to back anew (huge_pages.h).
    value += huge && !host_reports_free_pages ? "=1" : "=0";
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

void reexec_with_heap_tunables(char** argv) {
  const char* opt_out = std::getenv("SCALEFUSE_HUGE_PAGES");
  if (opt_out && std::strcmp(opt_out, "0") == 0) return;
  std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;  // one line
  if (!std::getline(in, mode)) return;
  const char* before = std::getenv("GLIBC_TUNABLES");
  // The balloon matters only where the page size is still ours to choose: not in the re-executed
  // process (its hugetlb is set), nor where the user set it, nor where the kernel offers no huge
  // pages or glibc has no hugetlb tunable.
  const std::string_view libc = gnu_get_libc_version();
  const bool reporting = !users_hugetlb(before) && gives_huge_pages(mode) && has_hugetlb_tunable(libc) &&
                         balloon_reports_free_pages();
  const std::optional<std::string> value = huge_page_tunables(before, mode, libc, reporting);
  if (!value) return;
  const std::string saved = before ? before : "";
  // Under `always` the kernel gives huge pages unasked: hugetlb=0 alone would not keep the heap
  // on 4 KiB pages. Set only if not set already (by a parent), so that undoing it after a failed
  // exec restores the start.
  const bool thp_disabled = disables_transparent_huge_pages(before, mode, reporting) &&
                            ::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0) == 0 &&
                            ::prctl(PR_SET_THP_DISABLE, 1, 0, 0, 0) == 0;
  if (setenv("GLIBC_TUNABLES", value->c_str(), 1) == 0) {
    execv("/proc/self/exe", argv);
    // Still here: the exec failed; carry on as started.
    if (before)
      setenv("GLIBC_TUNABLES", saved.c_str(), 1);
    else
      unsetenv("GLIBC_TUNABLES");
  }
  if (thp_disabled) ::prctl(PR_SET_THP_DISABLE, 0, 0, 0, 0);
}

}  // namespace sf
