/* Latency of dependent loads on this machine by working-set size, for telling which trees
 * fit in the cache a guest really gets (a VM may see much less of the L3 than lscpu lists;
 * see PERFORMANCE.md, "The guest's cache"). One thread follows a random cycle through the
 * 64-byte lines of a buffer of S MiB (2 MiB-aligned, transparent huge pages asked for, so
 * that the TLB does not add its misses), 2,000,000 loads per pass, and prints the median and
 * range of five passes after a warm-up pass, in nanoseconds per load.
 *
 *   gcc -O2 tools/memlat.c -o /tmp/memlat && /tmp/memlat 0.5 1 2 3 4 8 16 64
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <time.h>

#define LOADS 2000000
#define PASSES 6

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int by_value(const void* a, const void* b) {
  double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

int main(int argc, char** argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s MIB...\n", argv[0]);
    return 2;
  }
  for (int a = 1; a < argc; a++) {
    double mib = atof(argv[a]);
    size_t lines = (size_t)(mib * 1048576.0) / 64;
    if (lines < 2) {
      fprintf(stderr, "%s: working set too small\n", argv[a]);
      return 2;
    }
    size_t huge = 2u << 20, span = (lines * 64 + huge - 1) / huge * huge;
    uint64_t* p = aligned_alloc(huge, span);
    size_t* order = malloc(lines * sizeof *order);
    if (!p || !order) {
      fprintf(stderr, "%s MiB: out of memory\n", argv[a]);
      return 1;
    }
    madvise(p, span, MADV_HUGEPAGE);
    uint64_t s = 0x9E3779B97F4A7C15ull;
    for (size_t i = 0; i < lines; i++) order[i] = i;
    for (size_t i = lines - 1; i > 0; i--) { /* Fisher-Yates with xorshift64 */
      s ^= s << 13, s ^= s >> 7, s ^= s << 17;
      size_t j = s % (i + 1), t = order[i];
      order[i] = order[j], order[j] = t;
    }
    for (size_t k = 0; k < lines; k++) p[order[k] * 8] = order[(k + 1) % lines] * 8;
    double ns[PASSES];
    volatile uint64_t* v = p;
    uint64_t cur = order[0] * 8;
    for (int pass = 0; pass < PASSES; pass++) {
      double t = now();
      for (int i = 0; i < LOADS; i++) cur = v[cur];
      ns[pass] = (now() - t) * 1e9 / LOADS;
    }
    qsort(ns + 1, PASSES - 1, sizeof *ns, by_value);
    printf("%7.2f MiB: %6.1f ns per load (%.1f-%.1f)\n", mib, ns[3], ns[1], ns[PASSES - 1]);
    free(order);
    free(p);
  }
  return 0;
}
