#pragma once
// Transparent huge pages for malloc. The stock's leaves (2 KB each, a
// million or more at 1 um) and the update's scratch come from glibc's
// malloc in 4 KB pages, each first touch a page fault; on a virtual
// machine a fault costs microseconds (the blade at 1 um took 1.1 M of
// them, 13 s of system time). glibc's tunable glibc.malloc.hugetlb=1 has
// malloc ask the kernel for 2 MB pages (madvise), but glibc reads its
// tunables only when a program starts, so cutsim sets it and starts
// itself again (reexec_with_huge_pages).
#include <cstddef>
#include <optional>
#include <string>

namespace cutsim {

/// GLIBC_TUNABLES with glibc.malloc.hugetlb=1 added to `current` (null or
/// empty: none set), or nullopt where `current` already sets that tunable
/// (whatever its value: the user's choice stands).
std::optional<std::string> tunables_with_huge_pages(const char* current);

/// Whether malloc is glibc's (not a sanitizer's).
bool malloc_is_glibcs();

/// Whether the kernel gives transparent huge pages where madvise asks for
/// them: /sys/kernel/mm/transparent_hugepage/enabled reads "[always]" or
/// "[madvise]".
bool transparent_huge_pages_available();

/// Whether this process's malloc asks for huge pages: GLIBC_TUNABLES sets
/// glibc.malloc.hugetlb=1 and the kernel has them. (Under a sanitizer,
/// whose allocator is not glibc's, false.)
bool malloc_huge_pages();

/// Has malloc keep what is freed for the next allocations instead of
/// handing it back to the kernel: blocks up to 32 MB come from its heaps
/// (not each from a mapping of its own), and their tops are not trimmed.
/// A batch of moves frees the update's scratch that the next one
/// allocates again; handed back, each 2 MB page was faulted in and zeroed
/// again (raster40k: about 5 % more moves/s). What is kept is reused, so
/// the peak is what it was (the snowflake's the same; the blade's 6 %
/// higher with huge pages and this together). The heap also grows 64 MB
/// past each need: grown a few pages at a time, its new top came in 4 KB
/// pages, not huge ones (the blade at 1 um: 216k page faults, not 11k;
/// raster40k: 13k, not 3k).
void keep_freed_memory();

/// While alive, memory this process touches for the first time comes in
/// 4 KB pages, whatever malloc asks for (prctl PR_SET_THP_DISABLE; the
/// state before is restored after). For the export after a run, and for
/// `cutsim compare`: their meshes, distance blocks and glb buffers are
/// new memory written once or twice, and on the 2-core machine a 2 MB
/// page's first touch costs twice what its 512 small pages do (1.5 GB
/// touched: 1.3 s in huge pages, 0.6 s in small ones, unless just freed by
/// another process); the stock's leaves, touched again and again in no
/// set order, keep the huge pages they already have. (The snowflake's
/// export: 3.63-3.69 -> 3.23-3.39 s, its system time 1.4-2.2 -> 0.6-0.9 s.)
class SmallPagesForNewMemory {
public:
  SmallPagesForNewMemory();
  ~SmallPagesForNewMemory();
  SmallPagesForNewMemory(const SmallPagesForNewMemory&) = delete;
  SmallPagesForNewMemory& operator=(const SmallPagesForNewMemory&) = delete;
  /// Whether the kernel took the setting (false: nothing changed).
  bool active() const { return set_; }

private:
  bool set_ = false;
};

/// Whether a stock grid of about `estimated_bytes` (stock::
/// estimate_memory_bytes) should take its new memory in 4 KB pages
/// (SmallPagesForNewMemory over the simulation): below 2 GiB, yes. On the
/// 2-core virtual machine a 2 MB page first touched costs 3-4.5 ms where
/// the machine has handed its free memory back to the host (it does so
/// within a second of its being freed: free page reporting), 0.2 ms where
/// it has not, and 512 small pages some 0.8 ms either way. A run of
/// raster40k touches some 85 MB of new memory (its grid's leaves, the
/// update's scratch): its simulation took 0.33-0.51 s with huge pages,
/// by what ran before it, and 0.35-0.38 s with small ones; the
/// snowflake's (0.9 GB) bench 9.5-9.6 s and 9.1-9.2 s. The blade at
/// 1 um (3 GB), whose leaves the update visits in no set order, keeps its
/// huge pages: 38.7 s with them, 40.4 s without. CUTSIM_STOCK_PAGES=small
/// or =huge overrides the choice (huge: only where malloc asks for them,
/// malloc_huge_pages).
bool stock_wants_small_pages(std::size_t estimated_bytes);
/// The size from which stock_wants_small_pages says no (2 GiB).
inline constexpr std::size_t kStockHugePagesFrom = std::size_t(2) << 30;

/// Whether memory this process touches for the first time now comes in
/// huge pages: malloc asks for them (malloc_huge_pages) and they are not
/// turned off for the process (SmallPagesForNewMemory, or from its start).
bool huge_pages_for_new_memory();

/// Starts this program again (/proc/self/exe, the same arguments) with
/// glibc.malloc.hugetlb=1 added to GLIBC_TUNABLES, where that can help:
/// not when GLIBC_TUNABLES already sets it, CUTSIM_HUGE_PAGES=0, the
/// kernel has no transparent huge pages, under valgrind (LD_PRELOAD) or a
/// sanitizer. Returns only where it does not (or the exec fails).
void reexec_with_huge_pages(char** argv);

}  // namespace cutsim
