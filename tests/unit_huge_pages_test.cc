#include <gtest/gtest.h>

#include "scheduler/huge_pages.h"

using sf::huge_page_tunables;

TEST(HugePages, AsksGlibcOnlyWhereTheKernelWaitsToBeAsked) {
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never\n", "2.36"), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables(nullptr, "[always] madvise never\n", "2.36"), std::nullopt);  // given unasked
  EXPECT_EQ(huge_page_tunables(nullptr, "always madvise [never]\n", "2.36"), std::nullopt);  // not at all
  EXPECT_EQ(huge_page_tunables(nullptr, "", "2.36"), std::nullopt);
}

TEST(HugePages, NeedsAGlibcThatKnowsTheTunable) {
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.34"), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "2.35"), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "3.0"), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables(nullptr, "always [madvise] never", "unknown"), std::nullopt);
}

TEST(HugePages, KeepsTheUsersTunablesAndNeverLoops) {
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", "always [madvise] never", "2.36"),
            "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("", "always [madvise] never", "2.36"), "glibc.malloc.hugetlb=1");
  // Set already, by the user (0 = no) or by the re-execution itself.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0", "always [madvise] never", "2.36"), std::nullopt);
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=1", "always [madvise] never", "2.36"), std::nullopt);
}
