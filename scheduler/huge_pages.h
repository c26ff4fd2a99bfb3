#pragma once
// The heap's page size and growth. On the machines of sessions 19-37 a first touch of a fresh 4
// KiB page cost ~10 µs (a virtual machine's page fault), and a fusion job touches its voxel blocks,
// tile images and per-depth-map tables afresh many times over: a third of an integration's time
// went to page faults (bench/README.md, session 19). glibc's malloc asks the kernel for 2 MiB pages
// when started with GLIBC_TUNABLES=glibc.malloc.hugetlb=1, a setting read only at start-up, so the
// command-line program re-executes itself once with it. Allocation only: results do not change.
// Where the host takes free 2 MiB blocks back (a balloon that reports free pages, as on the
// machines since session 39) fresh huge pages are the slow ones, and it asks for 4 KiB pages
// instead (huge_page_tunables).
//
// That alone gives 2 MiB pages to the main thread's heap only. TBB's worker threads allocate from
// heaps of their own, which glibc grows by as little as each request needs, so a 2 MiB range is
// never faulted whole and they took 4 KiB faults (igea at 2 threads: 37 k faults, against 15 k
// with the settings below). The same re-execution therefore also sets how every heap grows: by
// 32 MiB at a time (top_pad), trimmed back only when 64 MiB lie free at its top (trim_threshold),
// and allocations under 32 MiB served from the heap (mmap_threshold, which glibc would otherwise
// keep at 128 KiB once top_pad is set, mapping every depth map's arrays afresh). They spare
// faults even where the kernel gives no huge pages, so the program re-executes in every mode.
// Measured: bench/README.md, session 37.
#include <optional>
#include <string>
#include <string_view>

namespace sf {

// The GLIBC_TUNABLES value to re-execute with, or nullopt if that would change nothing:
// `transparent_hugepage` is the kernel's /sys/kernel/mm/transparent_hugepage/enabled ("always
// [madvise] never": the madvise mode needs glibc to ask; "always" gives huge pages unasked, but
// only to ranges a heap has grown over whole, so the heap tunables matter there too: igea at 2
// threads took 67 k faults without them, 10 k with; "never" gives none, so hugetlb=0 there, but
// the heap tunables still spare faults: 104 k -> 77 k), `libc_version` glibc's (hugetlb exists
// from 2.35), `tunables` the current GLIBC_TUNABLES (null if unset). Every tunable it sets is
// kept: glibc.malloc.hugetlb set there is the user's choice (0 on a virtual machine whose host
// backs fresh 2 MiB pages slowly: bench/README.md, session 39), and the heap tunables it lacks are
// still added; nullopt once hugetlb and all three are set, as in the re-executed process itself.
// `host_reports_free_pages` (reports_free_pages below) asks for 4 KiB pages (hugetlb=0) in every
// mode: on a virtual machine whose balloon hands free 2 MiB blocks back to the host, huge pages are
// made of exactly those blocks, so a fresh one is backed anew by the host (0.37-0.57 GB/s for 128
// MiB after a few seconds idle), while 4 KiB pages mostly come from memory the guest still holds
// (~1-3 GB/s): igea's integration at 1 thread took 0.85x the time on 4 KiB pages, idle or run
// back to back (bench/README.md, session 46). The city block's eighth, whose field reuses its
// memory as bricks spill and reload, took 1.02-1.07x (sessions 42, 46); set
// GLIBC_TUNABLES=glibc.malloc.hugetlb=1 for jobs of many GB there. A hugetlb the user set is kept.
std::optional<std::string> huge_page_tunables(const char* tunables, std::string_view transparent_hugepage,
                                              std::string_view libc_version, bool host_reports_free_pages);

// Whether a virtio-balloon device's feature bits (the text of
// /sys/bus/virtio/drivers/virtio_balloon/*/features, bit 0 first) include free page reporting
// (VIRTIO_BALLOON_F_REPORTING, bit 5).
bool reports_free_pages(std::string_view balloon_features);

// Re-executes the running program (/proc/self/exe, same arguments and environment) with the
// tunables of huge_page_tunables(), unless SCALEFUSE_HUGE_PAGES=0. Where the balloon reports free
// pages and the kernel gives huge pages unasked (`always`), it also turns them off for the process
// (PR_SET_THP_DISABLE, kept across the exec), unless the user set glibc.malloc.hugetlb. Returns if it does not re-execute (not applicable,
// disabled, or the exec failed: the run then goes on with the pages it started with).
void reexec_with_huge_pages(char** argv);

}  // namespace sf
