#include <gtest/gtest.h>

#include "scheduler/huge_pages.h"

using sf::huge_page_tunables;

namespace {
// The heap tunables that come with glibc.malloc.hugetlb=1 (or =0 where the kernel gives no huge
// pages; scheduler/huge_pages.h).
const std::string kPad = ":glibc.malloc.top_pad=33554432", kMmap = ":glibc.malloc.mmap_threshold=33554432",
                  kTrim = ":glibc.malloc.trim_threshold=67108864";
const std::string kAll = "glibc.malloc.hugetlb=1" + kPad + kMmap + kTrim;
}  // namespace

TEST(HugePages, SetsTheHeapsInEveryTransparentHugePageMode) {
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never\n", "2.36"), kAll);
  // Given unasked, but only where a heap grows over a whole 2 MiB range.
  EXPECT_EQ(huge_page_tunables(nullptr, "[always] madvise never\n", "2.36"), kAll);
  // None at all: nothing to ask glibc for (hugetlb=0 still marks the re-execution), but the heaps.
  EXPECT_EQ(huge_page_tunables(nullptr, "always madvise [never]\n", "2.36"),
            "glibc.malloc.hugetlb=0" + kPad + kMmap + kTrim);
  EXPECT_EQ(huge_page_tunables(nullptr, "", "2.36"), std::nullopt);  // no mode read
  const std::string set_already = "glibc.malloc.hugetlb=0" + kPad + kMmap + kTrim;
  EXPECT_EQ(huge_page_tunables(set_already.c_str(), "always madvise [never]", "2.36"), std::nullopt);
}

TEST(HugePages, NeedsAGlibcThatKnowsTheTunable) {
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.34"), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.35"), kAll);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "3.0"), kAll);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "unknown"), std::nullopt);
}

TEST(HugePages, KeepsTheUsersTunablesAndNeverLoops) {
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", "always [madvise] never", "2.36"),
            "glibc.malloc.arena_max=2:" + kAll);
  EXPECT_EQ(huge_page_tunables("", "always [madvise] never", "2.36"), kAll);
  // A heap tunable the user set stays theirs.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.top_pad=0", "always [madvise] never", "2.36"),
            "glibc.malloc.top_pad=0:glibc.malloc.hugetlb=1" + kMmap + kTrim);
  EXPECT_EQ(huge_page_tunables("glibc.malloc.trim_threshold=1:glibc.malloc.mmap_threshold=2", "always [madvise] never", "2.36"),
            "glibc.malloc.trim_threshold=1:glibc.malloc.mmap_threshold=2:glibc.malloc.hugetlb=1" + kPad);
  // hugetlb set by the user (0 = no huge pages) keeps their choice and still gets the heap
  // tunables it lacks; once all are set (the re-execution's own environment) nothing changes.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0", "always [madvise] never", "2.36"),
            "glibc.malloc.hugetlb=0" + kPad + kMmap + kTrim);
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0:glibc.malloc.top_pad=0", "always [madvise] never", "2.36"),
            "glibc.malloc.hugetlb=0:glibc.malloc.top_pad=0" + kMmap + kTrim);
  EXPECT_EQ(huge_page_tunables(kAll.c_str(), "always [madvise] never", "2.36"), std::nullopt);
  const std::string no_huge = "glibc.malloc.hugetlb=0" + kPad + kMmap + kTrim;
  EXPECT_EQ(huge_page_tunables(no_huge.c_str(), "always [madvise] never", "2.36"), std::nullopt);
  // Whatever the start, the value returned is a fixed point: a second start re-executes no more.
  for (const char* start : {"", "glibc.malloc.hugetlb=0", "glibc.malloc.trim_threshold=5", "glibc.malloc.arena_max=1"}) {
    const std::optional<std::string> once = huge_page_tunables(start, "always [madvise] never", "2.36");
    ASSERT_TRUE(once.has_value()) << start;
    EXPECT_EQ(huge_page_tunables(once->c_str(), "always [madvise] never", "2.36"), std::nullopt) << start;
  }
}
