// The brick-by-brick extraction's scratch mailboxes (storage/mailbox.h) and its vertex order
// (engine/extract/voxel_set.h).
#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/extract/voxel_set.h"
#include "engine/error.h"
#include "storage/mailbox.h"

namespace sf {
namespace {

TEST(Mailbox, CollectsEachDestinationInSourceThenPostingOrder) {
  const ScratchFolder dir("scalefuse-mailbox-test");
  Mailbox box(dir.path(), "numbers");
  // Posted from many threads, out of order.
  tbb::parallel_for(0, 64, [&](int i) {
    const std::uint64_t dest = std::uint64_t(i % 4), src = std::uint64_t(63 - i);
    box.post(dest, src, std::vector<std::uint32_t>{std::uint32_t(i), std::uint32_t(1000 + i)});
  });
  box.post(7, 0, std::vector<std::uint32_t>{});  // nothing: no destination
  EXPECT_EQ(box.destinations(), (std::vector<std::uint64_t>{0, 1, 2, 3}));
  for (std::uint64_t dest = 0; dest < 4; ++dest) {
    const std::vector<std::uint32_t> got = box.collect<std::uint32_t>(dest);
    ASSERT_EQ(got.size(), 32u);
    // Sources ascend: src = 63 - i, so i descends.
    for (std::size_t k = 0; k < 16; ++k) {
      const std::uint32_t i = got[2 * k];
      EXPECT_EQ(i % 4, dest);
      EXPECT_EQ(got[2 * k + 1], 1000 + i);
      if (k > 0) {
        EXPECT_LT(i, got[2 * k - 2]);
      }
    }
  }
  EXPECT_TRUE(box.collect<std::uint32_t>(5).empty());
  EXPECT_GT(box.bytes_raw(), 0u);
  EXPECT_THROW(box.post(0, 0, std::vector<int>{1}), std::logic_error);  // the pass is over
}

TEST(Mailbox, LargeBlobsRoundTripAndFilesGoAway) {
  std::filesystem::path file;
  {
    const ScratchFolder dir("scalefuse-mailbox-test");
    Mailbox box(dir.path(), "big");
    std::vector<std::uint64_t> a(1 << 20), b(1000);
    for (std::size_t i = 0; i < a.size(); ++i) a[i] = i / 7;  // compressible, like voxel records
    for (std::size_t i = 0; i < b.size(); ++i) b[i] = ~i;
    box.post(9, 2, b);
    box.post(9, 1, a);
    const std::vector<std::uint64_t> got = box.collect<std::uint64_t>(9);
    ASSERT_EQ(got.size(), a.size() + b.size());
    EXPECT_TRUE(std::equal(a.begin(), a.end(), got.begin()));
    EXPECT_TRUE(std::equal(b.begin(), b.end(), got.begin() + std::ptrdiff_t(a.size())));
    file = dir.path() / "big.box";
    EXPECT_TRUE(std::filesystem::exists(file));
    EXPECT_LT(box.bytes_stored(), box.bytes_raw());
  }
  EXPECT_FALSE(std::filesystem::exists(file));
  EXPECT_FALSE(std::filesystem::exists(file.parent_path()));
}

TEST(Mailbox, ReopensWithTheCommittedBlobsOnly) {
  // A run posts from sources 1 and 2 and "commits" source 1 only (its blobs, after a sync);
  // killed, it leaves source 2's blob in the file. The next run sees source 1's blob, redoes
  // source 2 after it, and collects in (source, posting) order.
  const ScratchFolder dir("scalefuse-mailbox-reopen");
  std::vector<Mailbox::Blob> committed;
  {
    Mailbox box(dir.path(), "kept");
    box.keep_file();
    box.post(5, 1, std::vector<std::uint32_t>{10, 11});
    box.post(5, 2, std::vector<std::uint32_t>{99});  // uncommitted
    box.post(6, 1, std::vector<std::uint32_t>{12});
    committed = box.sync_blobs_from({1});
    ASSERT_EQ(committed.size(), 2u);
    EXPECT_EQ(committed[0].src, 1u);
    EXPECT_EQ(committed[1].dest, 6u);
    EXPECT_TRUE(box.sync_blobs_from({3}).empty());
  }
  ASSERT_TRUE(std::filesystem::exists(dir.path() / "kept.box"));
  {
    Mailbox box(dir.path(), "kept", committed);
    box.keep_file();
    EXPECT_TRUE(box.sync_blobs_from({1}).empty()) << "committed blobs are not new";
    box.post(5, 2, std::vector<std::uint32_t>{20});
    box.post(5, 0, std::vector<std::uint32_t>{7});
    const std::vector<Mailbox::Blob> fresh = box.sync_blobs_from({0, 2});
    EXPECT_EQ(fresh.size(), 2u);
    EXPECT_EQ(box.collect<std::uint32_t>(5), (std::vector<std::uint32_t>{7, 10, 11, 20}));
    EXPECT_EQ(box.collect<std::uint32_t>(6), (std::vector<std::uint32_t>{12}));
    EXPECT_EQ(box.raw_bytes(5), 16u);
    EXPECT_THROW(box.sync_blobs_from({2}), std::logic_error) << "no journal sync once collecting began";
    box.remove_file();
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "kept.box"));
  // A file shorter than its record says: refused, naming it.
  {
    Mailbox box(dir.path(), "short");
    box.keep_file();
    box.post(1, 1, std::vector<std::uint32_t>(1000, 3));
    committed = box.sync_blobs_from({1});
  }
  std::filesystem::resize_file(dir.path() / "short.box", 10);
  try {
    Mailbox box(dir.path(), "short", committed);
    ADD_FAILURE() << "a truncated scratch file was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("short.box"), std::string::npos) << e.what();
  }
}

// A cluster's tiles each post to their own file; the union of the files, read through their
// manifests, collects what one mailbox would have (sources are each one tile's).
TEST(Mailbox, AUnionOfTilesFilesCollectsAsOneMailbox) {
  const ScratchFolder dir("scalefuse-mailbox-test");
  Mailbox one(dir.path(), "one");
  std::vector<std::unique_ptr<Mailbox>> tiles;
  for (int t = 0; t < 3; ++t) tiles.push_back(std::make_unique<Mailbox>(dir.path() / ("tile" + std::to_string(t)), "box"));
  for (std::uint32_t i = 0; i < 60; ++i) {
    const std::uint64_t dest = i % 5, src = (i * 7) % 12;  // source s belongs to tile s % 3
    const std::vector<std::uint32_t> record{i, std::uint32_t(dest * 100 + src)};
    one.post(dest, src, record);
    tiles[src % 3]->post(dest, src, record);
  }
  std::vector<Mailbox::Part> parts;
  for (int t = 2; t >= 0; --t) {  // the order of the parts does not matter
    tiles[std::size_t(t)]->keep_file();
    const std::filesystem::path manifest = dir.path() / ("tile" + std::to_string(t)) / "pass.blobs";
    std::vector<BlobRecord> records;
    for (const Mailbox::Blob& b : tiles[std::size_t(t)]->blobs()) records.push_back({"box", b});
    write_blob_manifest(manifest, records);
    Mailbox::Part part{tiles[std::size_t(t)]->path(), {}};
    for (const BlobRecord& r : read_blob_manifest(manifest)) {
      EXPECT_EQ(r.box, "box");
      part.blobs.push_back(r.blob);
    }
    parts.push_back(std::move(part));
  }
  tiles.clear();  // the files stay (keep_file)
  Mailbox all(std::move(parts));
  EXPECT_EQ(all.destinations(), one.destinations());
  for (std::uint64_t dest = 0; dest < 5; ++dest) EXPECT_EQ(all.collect<std::uint32_t>(dest), one.collect<std::uint32_t>(dest));
  EXPECT_EQ(all.bytes_raw(), one.bytes_raw());
  EXPECT_THROW(all.post(0, 0, std::vector<int>{1}), std::logic_error);  // read-only
}

TEST(Mailbox, AUnionNamesAMissingOrShortFileAndManifestsAreChecked) {
  const ScratchFolder dir("scalefuse-mailbox-test");
  const std::filesystem::path file = dir.path() / "gone.box";
  // Opened lazily: making the union works, collecting from it names the file.
  const Mailbox gone(std::vector<Mailbox::Part>{{file, {{3, 1, 0, 0, 10, 40}}}});
  EXPECT_EQ(gone.destinations(), std::vector<std::uint64_t>{3});
  try {
    gone.collect<std::uint32_t>(3);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("gone.box"), std::string::npos) << e.what();
  }
  std::ofstream(dir.path() / "short.box") << "abc";
  const Mailbox short_one(std::vector<Mailbox::Part>{{dir.path() / "short.box", {{3, 1, 0, 0, 10, 40}}}});
  try {
    short_one.collect<std::uint32_t>(3);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("shorter than its tile's manifest says (10 bytes)"), std::string::npos) << e.what();
  }
  const std::filesystem::path manifest = dir.path() / "x.blobs";
  EXPECT_THROW(read_blob_manifest(manifest), InputError);  // missing
  write_blob_manifest(manifest, {{"box", {1, 2, 3, 4, 5, 6}}, {"other", {7, 8, 9, 10, 11, 12}}});
  const std::vector<BlobRecord> back = read_blob_manifest(manifest);
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[1].box, "other");
  EXPECT_EQ(back[1].blob.dest, 7u);
  EXPECT_EQ(back[1].blob.raw, 12u);
  for (const char* bad : {"", "scalefuse-blobs 2 0\nend\n", "scalefuse-blobs 1 2\nbox 1 2 3 4 5 6\nend\n",
                          "scalefuse-blobs 1 1\nbox 1 2 3 4 5 6\n", "scalefuse-blobs 1 1\nbox 1 2 x 4 5 6\nend\n"}) {
    std::ofstream(manifest) << bad;
    try {
      read_blob_manifest(manifest);
      FAIL() << "accepted: " << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("x.blobs"), std::string::npos) << e.what();
    }
  }
}

TEST(VertexOrder, MortonCodesByHand) {
  using extract_detail::home_code;
  using extract_detail::morton;
  EXPECT_EQ(morton(1, 0, 0), 1u);
  EXPECT_EQ(morton(0, 1, 0), 2u);
  EXPECT_EQ(morton(0, 0, 1), 4u);
  EXPECT_EQ(morton(3, 0, 0), 9u);           // x bits 0, 1 -> bits 0, 3
  EXPECT_EQ(morton(0, 2, 1), 16u + 4u);     // y bit 1 -> bit 4; z bit 0 -> bit 2
  EXPECT_EQ(morton((1u << 20), 0, 0), std::uint64_t{1} << 60);
  // A voxel of level l at x is the point x * 2^(18 - l) of the deepest lattice.
  EXPECT_EQ(home_code(VoxelKey::make(1, 1, 0, 0)), morton(1u << 17, 0, 0));
  EXPECT_EQ(home_code(VoxelKey::make(18, 5, 6, 7)), morton(5, 6, 7));
  // The root's upper face joins the last cell, as bricks take it.
  EXPECT_EQ(home_code(VoxelKey::make(0, 1, 1, 1)), morton((1u << 18) - 1, (1u << 18) - 1, (1u << 18) - 1));
  // Bricks of any level are contiguous: every voxel of brick (1, 0, 1) of level 2 lies in
  // [code(brick), code(brick) + 8^(18-2)).
  const std::uint64_t brick = morton(1, 0, 1) << (3 * 16);
  for (const VoxelKey k : {VoxelKey::make(2, 1, 0, 1), VoxelKey::make(4, 7, 3, 4), VoxelKey::make(3, 3, 1, 2)}) {
    EXPECT_GE(home_code(k), brick);
    EXPECT_LT(home_code(k), brick + (std::uint64_t{1} << (3 * 16)));
  }
  EXPECT_GE(home_code(VoxelKey::make(2, 2, 0, 1)), brick + (std::uint64_t{1} << (3 * 16)));  // the next brick in x
}

}  // namespace
}  // namespace sf
