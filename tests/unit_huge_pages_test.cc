#include <gtest/gtest.h>

#include "scheduler/huge_pages.h"

using sf::huge_page_tunables;

namespace {
// The heap tunables that come with glibc.malloc.hugetlb=1 (or =0 where the kernel gives no huge
// pages or the balloon reports free pages; scheduler/huge_pages.h).
const std::string kPad = ":glibc.malloc.top_pad=33554432", kMmap = ":glibc.malloc.mmap_threshold=33554432",
                  kTrim = ":glibc.malloc.trim_threshold=67108864";
const std::string kAll = "glibc.malloc.hugetlb=1" + kPad + kMmap + kTrim;
const std::string kNone = "glibc.malloc.hugetlb=0" + kPad + kMmap + kTrim;
}  // namespace

TEST(HugePages, SetsTheHeapsInEveryTransparentHugePageMode) {
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never\n", "2.36", false), kAll);
  // Given unasked, but only where a heap grows over a whole 2 MiB range.
  EXPECT_EQ(huge_page_tunables(nullptr, "[always] madvise never\n", "2.36", false), kAll);
  // None at all: nothing to ask glibc for (hugetlb=0 still marks the re-execution), but the heaps.
  EXPECT_EQ(huge_page_tunables(nullptr, "always madvise [never]\n", "2.36", false),
            kNone);
  EXPECT_EQ(huge_page_tunables(nullptr, "", "2.36", false), std::nullopt);  // no mode read
  EXPECT_EQ(huge_page_tunables(kNone.c_str(), "always madvise [never]", "2.36", false), std::nullopt);
}

TEST(HugePages, NeedsAGlibcThatKnowsTheTunable) {
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.34", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.35", false), kAll);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "3.0", false), kAll);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "unknown", false), std::nullopt);
}

TEST(HugePages, KeepsTheUsersTunablesAndNeverLoops) {
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", "always [madvise] never", "2.36", false),
            "glibc.malloc.arena_max=2:" + kAll);
  EXPECT_EQ(huge_page_tunables("", "always [madvise] never", "2.36", false), kAll);
  // A heap tunable the user set stays theirs.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.top_pad=0", "always [madvise] never", "2.36", false),
            "glibc.malloc.top_pad=0:glibc.malloc.hugetlb=1" + kMmap + kTrim);
  EXPECT_EQ(huge_page_tunables("glibc.malloc.trim_threshold=1:glibc.malloc.mmap_threshold=2", "always [madvise] never", "2.36", false),
            "glibc.malloc.trim_threshold=1:glibc.malloc.mmap_threshold=2:glibc.malloc.hugetlb=1" + kPad);
  // hugetlb set by the user (0 = no huge pages) keeps their choice and still gets the heap
  // tunables it lacks; once all are set (the re-execution's own environment) nothing changes.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0", "always [madvise] never", "2.36", false),
            kNone);
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0:glibc.malloc.top_pad=0", "always [madvise] never", "2.36", false),
            "glibc.malloc.hugetlb=0:glibc.malloc.top_pad=0" + kMmap + kTrim);
  EXPECT_EQ(huge_page_tunables(kAll.c_str(), "always [madvise] never", "2.36", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(kNone.c_str(), "always [madvise] never", "2.36", false), std::nullopt);
  // Whatever the start, mode and balloon, the value returned is a fixed point: a second start
  // re-executes no more, even if it reads the balloon differently.
  for (const char* start : {"", "glibc.malloc.hugetlb=0", "glibc.malloc.trim_threshold=5", "glibc.malloc.arena_max=1"})
    for (const char* mode : {"always [madvise] never", "[always] madvise never", "always madvise [never]"})
      for (const bool reporting : {false, true}) {
        const std::optional<std::string> once = huge_page_tunables(start, mode, "2.36", reporting);
        ASSERT_TRUE(once.has_value()) << start << mode << reporting;
        for (const bool again : {false, true})
          EXPECT_EQ(huge_page_tunables(once->c_str(), mode, "2.36", again), std::nullopt) << start << mode << reporting;
      }
}

TEST(HugePages, AsksForSmallPagesWhereTheHostTakesFreedBlocksBack) {
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.36", true), kNone);
  EXPECT_EQ(huge_page_tunables(nullptr, "[always] madvise never", "2.36", true), kNone);
  EXPECT_EQ(huge_page_tunables(nullptr, "always madvise [never]", "2.36", true), kNone);
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", "always [madvise] never", "2.36", true),
            "glibc.malloc.arena_max=2:" + kNone);
  // The user's hugetlb wins, and the re-execution's own environment stays a fixed point.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=1", "always [madvise] never", "2.36", true), kAll);
  EXPECT_EQ(huge_page_tunables(kNone.c_str(), "always [madvise] never", "2.36", true), std::nullopt);
  EXPECT_EQ(huge_page_tunables(kAll.c_str(), "always [madvise] never", "2.36", true), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.34", true), std::nullopt);
}

TEST(HugePages, ReadsTheBalloonsFreePageReportingBit) {
  // This project's machine (session 46), all 128 bits: 1, 2, 5, 7 and 32 (stats queue, deflate on
  // OOM, reporting, ring event index, version 1).
  EXPECT_TRUE(sf::reports_free_pages(
      "0110010100000000000000000000000010000000000000000000000000000000"
      "0000000000000000000000000000000000000000000000000000000000000000"));
  EXPECT_TRUE(sf::reports_free_pages("0110010100000000000000000000000010000000000000000000000000000000"));
  EXPECT_FALSE(sf::reports_free_pages("0110000000000000000000000000000010000000000000000000000000000000"));
  EXPECT_FALSE(sf::reports_free_pages("01100"));  // too short to hold bit 5
  EXPECT_FALSE(sf::reports_free_pages(""));
}

TEST(HugePages, TurnsTransparentHugePagesOffOnlyWhereTheKernelGivesThemUnasked) {
  // `always` with a reporting balloon: hugetlb=0 alone would leave the heap on huge pages.
  EXPECT_TRUE(sf::disables_transparent_huge_pages(nullptr, "[always] madvise never", true));
  EXPECT_FALSE(sf::disables_transparent_huge_pages(nullptr, "[always] madvise never", false));
  // `madvise` and `never` give none unasked: hugetlb=0 is enough.
  EXPECT_FALSE(sf::disables_transparent_huge_pages(nullptr, "always [madvise] never", true));
  EXPECT_FALSE(sf::disables_transparent_huge_pages(nullptr, "always madvise [never]", true));
  // The user's hugetlb decides, whatever the balloon: 0 means 4 KiB pages, 1 huge ones.
  EXPECT_TRUE(sf::disables_transparent_huge_pages("glibc.malloc.hugetlb=0", "[always] madvise never", false));
  EXPECT_TRUE(sf::disables_transparent_huge_pages("glibc.malloc.arena_max=1:glibc.malloc.hugetlb=0:glibc.malloc.top_pad=0",
                                                  "[always] madvise never", false));
  EXPECT_FALSE(sf::disables_transparent_huge_pages("glibc.malloc.hugetlb=1", "[always] madvise never", true));
  EXPECT_FALSE(sf::disables_transparent_huge_pages("glibc.malloc.hugetlb=1:glibc.malloc.top_pad=0", "[always] madvise never", true));
  // Other tunables leave it to the balloon.
  EXPECT_TRUE(sf::disables_transparent_huge_pages("glibc.malloc.top_pad=0", "[always] madvise never", true));
}
