// A stage's blob manifest (JOB/cluster/tile-K/<stage>.blobs).
#include "fuzz/fuzz_util.h"
#include "storage/mailbox.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = sf::fuzz::put("stage.blobs", data, size);
  sf::fuzz::expect_accept_or_input_error([&] { (void)sf::read_blob_manifest(path); });
  return 0;
}
