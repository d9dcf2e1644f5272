// The server's static thread-local storage, which glibc carves from the top of every thread's
// stack: civetweb's HTTP workers, as Debian builds it, get 100 KB stacks (a worker that
// overflowed its stack in a debugger sat in a 0x19000-byte mapping above its guard page), so
// every kilobyte held in thread_local objects is a kilobyte less for a request's handler. When
// the fit's per-thread basis tables sat there, twice over once the fit had an AVX2 build (53 KB
// of 56 KB), an HTTP error page ran a worker off its stack and killed the server.
#include <elf.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "gtest/gtest.h"
#include "tests/testing/test_paths.h"

namespace tempokey::server::http {
namespace {

// The memory size of `path`'s PT_TLS segment (its static thread-local storage), read from the
// ELF headers themselves; -1 when the file is not a 64-bit ELF file.
std::int64_t StaticTlsBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  Elf64_Ehdr header{};
  if (!in.read(reinterpret_cast<char*>(&header), sizeof header)) return -1;
  if (header.e_ident[EI_MAG0] != ELFMAG0 || header.e_ident[EI_MAG1] != ELFMAG1 ||
      header.e_ident[EI_MAG2] != ELFMAG2 || header.e_ident[EI_MAG3] != ELFMAG3 ||
      header.e_ident[EI_CLASS] != ELFCLASS64) {
    return -1;
  }
  for (int i = 0; i < header.e_phnum; ++i) {
    Elf64_Phdr segment{};
    in.seekg(static_cast<std::streamoff>(header.e_phoff + i * header.e_phentsize));
    if (!in.read(reinterpret_cast<char*>(&segment), sizeof segment)) return -1;
    if (segment.p_type == PT_TLS) return static_cast<std::int64_t>(segment.p_memsz);
  }
  return 0;
}

// The same size as binutils' readelf reports it (the TLS line's MemSiz), -1 without one.
std::int64_t ReadelfTlsBytes(const std::string& path) {
  FILE* pipe = ::popen(("readelf -lW '" + path + "' 2>/dev/null").c_str(), "r");
  if (pipe == nullptr) return -1;
  std::int64_t bytes = -1;
  char line[512];
  while (std::fgets(line, sizeof line, pipe) != nullptr) {
    unsigned long long offset = 0, vaddr = 0, paddr = 0, filesz = 0, memsz = 0;
    if (std::sscanf(line, " TLS %llx %llx %llx %llx %llx", &offset, &vaddr, &paddr, &filesz,
                    &memsz) == 5) {
      bytes = static_cast<std::int64_t>(memsz);
    }
  }
  ::pclose(pipe);
  return bytes;
}

TEST(WorkerStackTest, TheServerKeepsItsThreadLocalStorageSmallBesideCivetwebs100KbStacks) {
  const std::string server = testing::BinaryDir() + "/server/tempokey-server";
  const std::int64_t tls = StaticTlsBytes(server);
  ASSERT_GE(tls, 0) << server << " is not a 64-bit ELF file";
  // Read as a tool we did not write reads it.
  EXPECT_EQ(tls, ReadelfTlsBytes(server));
  // 2.9 KB today (a random engine's state the largest part); 16 KB leaves a handler about 84 KB
  // (the shared libraries add their own TLS, libc's about 0.1 KB).
  EXPECT_LE(tls, 16 * 1024) << server << " holds " << tls
                            << " bytes of thread_local objects in every thread's stack";
}

}  // namespace
}  // namespace tempokey::server::http
