#include "proto/prefault.h"

#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>

namespace tempokey::wire {

bool PrefaultForWriting(void* begin, std::size_t bytes) {
#ifdef MADV_POPULATE_WRITE
  if (bytes < kMinPrefaultBytes) return false;
  const auto page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
  // madvise() wants page-aligned addresses: only the whole pages inside the range, so nothing
  // outside what the caller owns is touched.
  const auto start = reinterpret_cast<std::uintptr_t>(begin);
  const std::uintptr_t first = (start + page - 1) / page * page;
  const std::uintptr_t end = (start + bytes) / page * page;
  if (end <= first) return false;
  return madvise(reinterpret_cast<void*>(first), end - first, MADV_POPULATE_WRITE) == 0;
#else
  (void)begin;
  (void)bytes;
  return false;
#endif
}

}  // namespace tempokey::wire
