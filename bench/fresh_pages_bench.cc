// What writing into memory the process has not written before costs on this machine, beside
// writing it again: the floor under an upload, whose stored clip is new memory, and whose gRPC
// read buffers and parsed slices are new memory whenever glibc maps them afresh (allocations of
// 1 MiB and more in the server). Four ways, each on a fresh anonymous mapping, written in 1 MiB
// copies as the server's upload writes its samples:
//   plain      advised MADV_NOHUGEPAGE: the first write faults every base page in;
//   populated  the same, MADV_POPULATE_WRITE first (what the clip assembler does for a channel's
//              grown capacity: PrefaultForWriting(), proto/prefault.h), then the write;
//   rewrite    the populated mapping written a second time;
//   huge       2 MiB-aligned, advised MADV_HUGEPAGE, populated whole (2 MiB pages), then written:
//              shown only when transparent huge pages are not "[never]" and the kernel takes the
//              advice.
// Prints each as ms per 50 MB and MB/s of what is written (the median of the repeats), and the
// kernel's transparent huge page mode.
//
//   fresh_pages_bench [--mb=50] [--repeats=5]
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

namespace tempokey::bench {
namespace {

#ifndef MADV_POPULATE_WRITE
constexpr int MADV_POPULATE_WRITE = 23;  // Linux 5.14
#endif

using Clock = std::chrono::steady_clock;
constexpr std::size_t kPiece = std::size_t{1} << 20;
constexpr std::size_t kHugePage = std::size_t{2} << 20;

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// A fresh anonymous mapping of `bytes`, aligned to `alignment` (a power of two, at least a page).
class Mapping {
 public:
  Mapping(std::size_t bytes, std::size_t alignment) : length_(bytes + alignment) {
    void* p = mmap(nullptr, length_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    base_ = p == MAP_FAILED ? nullptr : static_cast<char*>(p);
    const auto at = reinterpret_cast<std::uintptr_t>(base_);
    data_ = reinterpret_cast<char*>((at + alignment - 1) & ~(alignment - 1));
  }
  ~Mapping() {
    if (base_ != nullptr) munmap(base_, length_);
  }
  Mapping(const Mapping&) = delete;
  Mapping& operator=(const Mapping&) = delete;

  bool ok() const { return base_ != nullptr; }
  char* data() const { return data_; }

 private:
  std::size_t length_;
  char* base_ = nullptr;
  char* data_ = nullptr;
};

void WriteAll(char* dest, std::size_t bytes, const std::vector<char>& piece) {
  for (std::size_t at = 0; at < bytes; at += kPiece) {
    std::memcpy(dest + at, piece.data(), std::min(kPiece, bytes - at));
  }
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

std::string HugePageMode() {
  std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;
  std::getline(in, mode);
  return mode.empty() ? "unknown" : mode;
}

// Kilobytes of this process's anonymous memory in transparent huge pages; -1 when unknown.
double AnonHugeKilobytes() {
  std::ifstream in("/proc/self/smaps_rollup");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("AnonHugePages:", 0) == 0) return std::atof(line.c_str() + 14);
  }
  return -1.0;
}

// Milliseconds of each way, one repeat; a way the kernel refuses is left out (negative). And the
// share of the huge way's mapping the kernel did give 2 MiB pages (under memory pressure it falls
// back to base pages).
struct Repeat {
  double plain = -1.0, populated = -1.0, rewrite = -1.0, huge = -1.0;
  double huge_share = -1.0;
};

Repeat MeasureOnce(std::size_t bytes, std::size_t page, const std::vector<char>& piece) {
  Repeat r;
  {
    Mapping m(bytes, page);
    if (!m.ok()) return r;
    madvise(m.data(), bytes, MADV_NOHUGEPAGE);
    const auto start = Clock::now();
    WriteAll(m.data(), bytes, piece);
    r.plain = MillisecondsSince(start);
  }
  {
    Mapping m(bytes, page);
    if (m.ok()) {
      madvise(m.data(), bytes, MADV_NOHUGEPAGE);
      const auto start = Clock::now();
      if (madvise(m.data(), bytes, MADV_POPULATE_WRITE) == 0) {
        WriteAll(m.data(), bytes, piece);
        r.populated = MillisecondsSince(start);
        const auto again = Clock::now();
        WriteAll(m.data(), bytes, piece);
        r.rewrite = MillisecondsSince(again);
      }
    }
  }
  if (HugePageMode().find("[never]") == std::string::npos) {
    const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
    Mapping m(rounded, kHugePage);
    const double huge_before = AnonHugeKilobytes();
    if (m.ok() && madvise(m.data(), rounded, MADV_HUGEPAGE) == 0) {
      const auto start = Clock::now();
      if (madvise(m.data(), rounded, MADV_POPULATE_WRITE) == 0) {
        WriteAll(m.data(), bytes, piece);
        r.huge = MillisecondsSince(start);
        const double huge_after = AnonHugeKilobytes();
        if (huge_before >= 0.0 && huge_after >= 0.0) {
          r.huge_share = (huge_after - huge_before) * 1024.0 / static_cast<double>(rounded);
        }
      }
    }
  }
  return r;
}

int Run(std::size_t bytes, int repeats) {
  const auto page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  std::vector<char> piece(kPiece);
  for (std::size_t i = 0; i < piece.size(); ++i) piece[i] = static_cast<char>(i * 31);
  std::vector<double> plain, populated, rewrite, huge, huge_share;
  for (int i = 0; i < repeats; ++i) {
    const Repeat r = MeasureOnce(bytes, page, piece);
    if (r.plain < 0.0) {
      std::fprintf(stderr, "mmap of %zu bytes failed\n", bytes);
      return 1;
    }
    plain.push_back(r.plain);
    if (r.populated >= 0.0) populated.push_back(r.populated);
    if (r.rewrite >= 0.0) rewrite.push_back(r.rewrite);
    if (r.huge >= 0.0) huge.push_back(r.huge);
    if (r.huge_share >= 0.0) huge_share.push_back(r.huge_share);
  }
  const double per50 = 50e6 / static_cast<double>(bytes);
  auto line = [&](const char* name, const std::vector<double>& ms, const char* missing) {
    if (ms.empty()) {
      std::printf("  %-10s %s\n", name, missing);
      return;
    }
    const double median = Median(ms);
    std::printf("  %-10s %8.1f ms per 50 MB  %8.0f MB/s\n", name, median * per50,
                static_cast<double>(bytes) / 1e6 / (median / 1e3));
  };
  std::printf("writing %.1f MB in 1 MiB copies, median of %d; %zu-byte pages; transparent huge "
              "pages: %s\n",
              static_cast<double>(bytes) / 1e6, repeats, page, HugePageMode().c_str());
  line("plain", plain, "");
  line("populated", populated, "not measured: MADV_POPULATE_WRITE needs Linux 5.14");
  line("rewrite", rewrite, "not measured: MADV_POPULATE_WRITE needs Linux 5.14");
  line("huge", huge,
       "not measured: transparent huge pages are off, or the kernel refused the advice");
  if (!huge_share.empty()) {
    std::printf("  %-10s %.0f %% of the huge way's mapping in 2 MiB pages (median)\n", "",
                100.0 * Median(huge_share));
  }
  return 0;
}

}  // namespace
}  // namespace tempokey::bench

int main(int argc, char** argv) {
  double mb = 50.0;
  int repeats = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg.rfind("--mb=", 0) == 0) {
      mb = std::atof(argv[i] + 5);
    } else if (arg.rfind("--repeats=", 0) == 0) {
      repeats = std::atoi(argv[i] + 10);
    } else {
      std::fprintf(stderr, "usage: fresh_pages_bench [--mb=50] [--repeats=5]\n");
      return 2;
    }
  }
  if (!(mb >= 1.0 && mb <= 4096.0) || repeats < 1 || repeats > 100) {
    std::fprintf(stderr, "--mb must be in [1, 4096] and --repeats in [1, 100]\n");
    return 2;
  }
  return tempokey::bench::Run(static_cast<std::size_t>(mb * 1e6), repeats);
}
