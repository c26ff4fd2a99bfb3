// How fast this machine hands out fresh memory: the first touch of anonymous pages, 4 KiB pages
// against transparent huge pages (madvise), three rounds each in one process (a round maps, touches
// one byte per 4 KiB, then unmaps). Tells whether the program's choice of 4 KiB pages where the
// virtio balloon reports free pages suits a machine, or `GLIBC_TUNABLES=glibc.malloc.hugetlb=1`
// should override it (docs/architecture.md, memory budget): on a virtual machine whose host takes
// freed guest memory back, the first round of huge pages runs at a fraction of the 4 KiB rate
// (run it after a few seconds idle, and with 128 MiB or more: the guest keeps a few 2 MiB blocks
// backed), and a fusion job's field is all first rounds; later rounds reuse the pages the process
// just freed.
// Build and run: g++ -O2 -o /tmp/first_touch bench/first_touch.cc && /tmp/first_touch [MiB=256]
#include <sys/mman.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <initializer_list>

int main(int argc, char** argv) {
  const std::size_t mib = argc > 1 ? std::strtoul(argv[1], nullptr, 10) : 256;
  const std::size_t bytes = mib << 20;
  for (const bool huge : {true, false}) {  // huge pages first: the 4 KiB rounds would free memory they could reuse
    for (int round = 1; round <= 3; ++round) {
      void* const map = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
      if (map == MAP_FAILED) {
        std::perror("first_touch: mmap");
        return 1;
      }
      if (huge && madvise(map, bytes, MADV_HUGEPAGE) != 0) std::perror("first_touch: madvise (no huge pages)");
      volatile char* const p = static_cast<volatile char*>(map);
      const auto start = std::chrono::steady_clock::now();
      for (std::size_t i = 0; i < bytes; i += 4096) p[i] = 1;
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      std::printf("%-10s round %d: %zu MiB in %.3f s, %.2f GB/s\n", huge ? "2 MiB THP" : "4 KiB", round, mib,
                  seconds, double(bytes) / seconds / 1e9);
      munmap(map, bytes);
    }
  }
  return 0;
}
