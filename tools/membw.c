/* Memory read bandwidth of this machine with 1 and 2 threads, for judging whether a ray set
 * that streams its rays from DRAM can scale with threads (see the README's benchmarking
 * section). Each thread sums its own 256 MB array eight times with AVX loads.
 *
 *   gcc -O2 -mavx2 -pthread tools/membw.c -o /tmp/membw && /tmp/membw
 */
#include <immintrin.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define FLOATS (64u << 20) /* per thread: 256 MB */
#define PASSES 8

static float* arrays[2];
static volatile float sums[2];

static void* sum_array(void* arg) {
  long i = (long)arg;
  const float* p = arrays[i];
  __m256 s = _mm256_setzero_ps();
  for (int pass = 0; pass < PASSES; pass++)
    for (size_t k = 0; k < FLOATS; k += 8) s = _mm256_add_ps(s, _mm256_load_ps(p + k));
  float lanes[8];
  _mm256_storeu_ps(lanes, s);
  sums[i] = lanes[0];
  return NULL;
}

static double seconds(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + t.tv_nsec * 1e-9;
}

int main(void) {
  for (int i = 0; i < 2; i++) {
    arrays[i] = aligned_alloc(64, (size_t)FLOATS * 4);
    if (!arrays[i]) return 1;
    memset(arrays[i], 0, (size_t)FLOATS * 4);
  }
  const double bytes = (double)PASSES * FLOATS * 4;
  for (int run = 0; run < 3; run++) {
    double t0 = seconds();
    sum_array((void*)0);
    double one = bytes / (seconds() - t0) / 1e9;
    pthread_t a, b;
    t0 = seconds();
    pthread_create(&a, NULL, sum_array, (void*)0);
    pthread_create(&b, NULL, sum_array, (void*)1);
    pthread_join(a, NULL);
    pthread_join(b, NULL);
    double two = 2 * bytes / (seconds() - t0) / 1e9;
    printf("run %d: 1 thread %.1f GB/s, 2 threads %.1f GB/s together (%.2fx)\n", run + 1, one, two, two / one);
  }
  return sums[0] + sums[1] != 0; /* always 0: keeps the sums alive */
}
