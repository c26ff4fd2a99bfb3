#pragma once
// The heap's page size and growth. On the machines of sessions 19-37 a first touch of a fresh 4
// KiB page cost ~10 µs (a virtual machine's page fault), and a fusion job touches its voxel blocks,
// tile images and per-depth-map tables afresh many times over: a third of an integration's time
// went to page faults (bench/README.md, session 19). glibc's malloc asks the kernel for 2 MiB pages
// when started with GLIBC_TUNABLES=glibc.malloc.hugetlb=1, a setting read only at start-up, so the
// command-line program re-executes itself once with it. Allocation only: results do not change.
// Where the host takes free 2 MiB blocks back (a virtio balloon that reports free pages) it asks
// for 4 KiB pages instead (huge_page_tunables): there fresh huge pages are the slow ones on the
// machines since session 39. The machines of sessions 19-37 reported free pages too, but their 4
// KiB faults cost ~10 µs each and huge pages won there; on such a machine set
// GLIBC_TUNABLES=glibc.malloc.hugetlb=1 (bench/first_touch.cc tells which kind one is on).
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
// kept: glibc.malloc.hugetlb set there is the user's choice, and the heap tunables it lacks are
// still added; nullopt once hugetlb and all three are set, as in the re-executed process itself.
// `host_reports_free_pages` (reports_free_pages below) asks for 4 KiB pages (hugetlb=0) in every
// mode: the kernel hands free 2 MiB blocks back to the host, and huge pages are made of exactly
// those blocks, so a fresh one is backed anew by the host, while 4 KiB pages mostly come from
// memory the guest still holds. Measured on a whole job rather than a probe (a few of the
// guest's free 2 MiB blocks are always still backed): igea's integration took 0.82-0.85x the
// time on 4 KiB pages; jobs whose fields outgrow the memory the guest holds can lose (city
// eighth 1.02-1.07x; docs/architecture.md, bench/README.md session 46).
std::optional<std::string> huge_page_tunables(const char* tunables, std::string_view transparent_hugepage,
                                              std::string_view libc_version, bool host_reports_free_pages);

// Whether a virtio-balloon device's feature bits (the text of
// /sys/bus/virtio/drivers/virtio_balloon/*/features, bit 0 first) include free page reporting
// (VIRTIO_BALLOON_F_REPORTING, bit 5).
bool reports_free_pages(std::string_view balloon_features);

// Whether the re-execution also turns transparent huge pages off for the process
// (PR_SET_THP_DISABLE): where the kernel gives them unasked (`always`) and the heap is to be on 4
// KiB pages, by the user's glibc.malloc.hugetlb=0 or, where the user set none, by the balloon.
bool disables_transparent_huge_pages(const char* tunables, std::string_view transparent_hugepage,
                                     bool host_reports_free_pages);

// Re-executes the running program (/proc/self/exe, same arguments and environment) with the
// tunables of huge_page_tunables(), unless SCALEFUSE_HUGE_PAGES=0, and turns transparent huge
// pages off first where disables_transparent_huge_pages says so (kept across the exec). Returns if
// it does not re-execute (not applicable, disabled, or the exec failed: the run then goes on as
// started).
void reexec_with_heap_tunables(char** argv);

}  // namespace sf
