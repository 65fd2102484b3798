#include "cutsim/core/huge_pages.h"

#include <malloc.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <climits>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

namespace cutsim {

namespace {
constexpr const char* kTunable = "glibc.malloc.hugetlb";

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define CUTSIM_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define CUTSIM_SANITIZED 1
#endif
#endif
#ifdef CUTSIM_SANITIZED
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

// The value GLIBC_TUNABLES (`name=value` items joined by ':') gives
// glibc.malloc.hugetlb, or nullopt.
std::optional<std::string> tunable_value(const char* tunables) {
  if (!tunables) return std::nullopt;
  std::stringstream in(tunables);
  std::string item;
  const std::string key = std::string(kTunable) + "=";
  std::optional<std::string> value;
  while (std::getline(in, item, ':'))
    if (item.rfind(key, 0) == 0) value = item.substr(key.size());  // (the last one counts, as in glibc)
  return value;
}
}  // namespace

std::optional<std::string> tunables_with_huge_pages(const char* current) {
  if (tunable_value(current)) return std::nullopt;
  const std::string add = std::string(kTunable) + "=1";
  if (!current || !*current) return add;
  return std::string(current) + ":" + add;
}

bool malloc_is_glibcs() { return !kSanitized; }

bool transparent_huge_pages_available() {
  std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string line;
  if (!std::getline(in, line)) return false;
  return line.find("[always]") != std::string::npos || line.find("[madvise]") != std::string::npos;
}

bool malloc_huge_pages() {
  if (kSanitized) return false;
  return tunable_value(std::getenv("GLIBC_TUNABLES")) == "1" && transparent_huge_pages_available();
}

void keep_freed_memory() {
  if (kSanitized) return;
  ::mallopt(M_MMAP_THRESHOLD, 32 << 20);  // (glibc's largest)
  ::mallopt(M_TRIM_THRESHOLD, INT_MAX);
  ::mallopt(M_TOP_PAD, 64 << 20);
}

SmallPagesForNewMemory::SmallPagesForNewMemory() {
  // (Only where huge pages were on: a process that had them off keeps it.)
  if (::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0) == 0) set_ = ::prctl(PR_SET_THP_DISABLE, 1, 0, 0, 0) == 0;
}

SmallPagesForNewMemory::~SmallPagesForNewMemory() {
  if (set_) ::prctl(PR_SET_THP_DISABLE, 0, 0, 0, 0);
}

bool huge_pages_for_new_memory() {
  return malloc_huge_pages() && ::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0) == 0;
}

bool stock_wants_small_pages(std::size_t estimated_bytes) {
  if (const char* opt = std::getenv("CUTSIM_STOCK_PAGES")) {
    if (std::strcmp(opt, "small") == 0) return true;
    if (std::strcmp(opt, "huge") == 0) return false;
  }
  return estimated_bytes < kStockHugePagesFrom;
}

void reexec_with_huge_pages(char** argv) {
  if (kSanitized) return;
  if (const char* opt = std::getenv("CUTSIM_HUGE_PAGES"); opt && std::strcmp(opt, "0") == 0) return;
  // Valgrind runs the program through its preloads; a new exec would leave it.
  if (const char* pre = std::getenv("LD_PRELOAD"); pre && std::strstr(pre, "vgpreload")) return;
  const char* was = std::getenv("GLIBC_TUNABLES");
  const std::optional<std::string> tunables = tunables_with_huge_pages(was);
  if (!tunables || !transparent_huge_pages_available()) return;
  const std::optional<std::string> before = was ? std::optional<std::string>(was) : std::nullopt;
  if (::setenv("GLIBC_TUNABLES", tunables->c_str(), 1) != 0) return;
  ::execv("/proc/self/exe", argv);
  // Failed: run as we are, with the variable as it was (so that
  // malloc_huge_pages tells the truth).
  if (before) ::setenv("GLIBC_TUNABLES", before->c_str(), 1);
  else ::unsetenv("GLIBC_TUNABLES");
}

}  // namespace cutsim
