// What writing into memory the process has not written before costs on this machine, beside
// writing it again: the floor under an upload, whose stored clip is new memory, and whose gRPC
// read buffers and parsed slices are new memory whenever glibc maps them afresh (allocations of
// 1 MiB and more in the server). Four ways, each on a fresh anonymous mapping of the same size,
// written in 1 MiB copies as the server's upload writes its samples:
//   plain      the first write faults every 4 KiB page in;
//   populated  MADV_POPULATE_WRITE maps the pages first (what the clip assembler does), then the
//              first write;
//   rewrite    the populated mapping written a second time;
//   huge       a 2 MiB-aligned mapping advised MADV_HUGEPAGE, populated, then written (needs
//              transparent huge pages in "madvise" or "always" mode).
// Prints each as ms per 50 MB and MB/s, the median of the repeats.
//
//   fresh_pages_bench [--mb=50] [--repeats=5]
#include <sys/mman.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
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

struct Times {
  std::vector<double> plain, populated, rewrite, huge;
};

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

int Run(std::size_t bytes, int repeats) {
  std::vector<char> piece(kPiece);
  for (std::size_t i = 0; i < piece.size(); ++i) piece[i] = static_cast<char>(i * 31);
  Times t;
  for (int r = 0; r < repeats; ++r) {
    {
      Mapping m(bytes, 4096);
      if (!m.ok()) return std::fprintf(stderr, "mmap of %zu bytes failed\n", bytes), 1;
      const auto start = Clock::now();
      WriteAll(m.data(), bytes, piece);
      t.plain.push_back(MillisecondsSince(start));
    }
    {
      Mapping m(bytes, 4096);
      if (!m.ok()) return std::fprintf(stderr, "mmap of %zu bytes failed\n", bytes), 1;
      const auto start = Clock::now();
      if (madvise(m.data(), bytes, MADV_POPULATE_WRITE) != 0) {
        return std::fprintf(stderr, "MADV_POPULATE_WRITE failed (Linux 5.14 or later)\n"), 1;
      }
      WriteAll(m.data(), bytes, piece);
      t.populated.push_back(MillisecondsSince(start));
      const auto again = Clock::now();
      WriteAll(m.data(), bytes, piece);
      t.rewrite.push_back(MillisecondsSince(again));
    }
    {
      const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
      Mapping m(rounded, kHugePage);
      if (!m.ok()) return std::fprintf(stderr, "mmap of %zu bytes failed\n", rounded), 1;
      const auto start = Clock::now();
      madvise(m.data(), rounded, MADV_HUGEPAGE);  // no effect where THP is "never"
      madvise(m.data(), rounded, MADV_POPULATE_WRITE);
      WriteAll(m.data(), bytes, piece);
      t.huge.push_back(MillisecondsSince(start));
    }
  }
  const double per50 = 50e6 / static_cast<double>(bytes);
  auto line = [&](const char* name, const std::vector<double>& ms) {
    const double median = Median(ms);
    std::printf("  %-10s %8.1f ms per 50 MB  %8.0f MB/s\n", name, median * per50,
                static_cast<double>(bytes) / 1e6 / (median / 1e3));
  };
  std::printf("writing %.1f MB in 1 MiB copies, median of %d\n", static_cast<double>(bytes) / 1e6,
              repeats);
  line("plain", t.plain);
  line("populated", t.populated);
  line("rewrite", t.rewrite);
  line("huge", t.huge);
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
