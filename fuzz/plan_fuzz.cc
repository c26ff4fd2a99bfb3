// A cluster plan (JOB/plan.json).
#include "fuzz/fuzz_util.h"
#include "scheduler/cluster.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sf::fuzz::put("job/plan.json", data, size);
  sf::fuzz::expect_accept_or_input_error([&] { (void)sf::read_cluster_plan(sf::fuzz::work_dir() / "job"); });
  return 0;
}
