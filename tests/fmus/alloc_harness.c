/* Counts the allocations a controller FMU (FMI 3, the four-tank problem: value references 1-4
 * in, 5-6 out) makes while it steps, malloc & co. interposed by this executable
 * (tests/fmus/test_controller_fmu.py). Usage: alloc_harness LIBRARY TOKEN TS RESOURCES */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"

static int counting = 0;
static long count = 0;
extern void *__libc_malloc(size_t);
extern void *__libc_calloc(size_t, size_t);
extern void *__libc_realloc(void *, size_t);
extern void *__libc_memalign(size_t, size_t);
extern void __libc_free(void *);
void *malloc(size_t n) { count += counting; return __libc_malloc(n); }
void *calloc(size_t a, size_t b) { count += counting; return __libc_calloc(a, b); }
void *realloc(void *p, size_t n) { count += counting; return __libc_realloc(p, n); }
void free(void *p) { __libc_free(p); }
int posix_memalign(void **p, size_t a, size_t n) {
  count += counting;
  *p = __libc_memalign(a, n);
  return *p ? 0 : 12;
}

#define SYM(T, name) T *name = (T *)dlsym(lib, #name); if (!name) return 2;

int main(int argc, char **argv) {
  if (argc < 5) return 2;
  void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
  if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 2; }
  SYM(fmi3InstantiateCoSimulationTYPE, fmi3InstantiateCoSimulation)
  SYM(fmi3EnterInitializationModeTYPE, fmi3EnterInitializationMode)
  SYM(fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode)
  SYM(fmi3SetFloat64TYPE, fmi3SetFloat64)
  SYM(fmi3GetFloat64TYPE, fmi3GetFloat64)
  SYM(fmi3DoStepTYPE, fmi3DoStep)
  SYM(fmi3FreeInstanceTYPE, fmi3FreeInstance)
  const double ts = atof(argv[3]);
  counting = 1;
  fmi3Instance c = fmi3InstantiateCoSimulation("mpc", argv[2], argv[4], fmi3False, fmi3False,
                                               fmi3False, fmi3False, NULL, 0, NULL, NULL, NULL);
  if (!c || fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) ||
      fmi3ExitInitializationMode(c)) return 2;
  const fmi3ValueReference in[4] = {1, 2, 3, 4}, out[2] = {5, 6};
  double y[4] = {0.62, 0.71, 1.3, 1.4}, u[2] = {0, 0}, t = 0.0;
  fmi3Boolean a, b, e;
  fmi3Float64 last;
  int bad = 0;
  const long at_instantiation = count;
  count = 0;
  for (int k = 0; k < 200; k++, t += ts) {
    y[0] += 0.05 * (y[2] - y[0]);
    y[1] += 0.05 * (y[3] - y[1]);
    const double h1 = y[0];
    if (k == 50) y[2] = 0.7, y[3] = 0.8;   /* a set-point step (the paper's law's governor) */
    if (k == 100) y[0] = NAN;   /* one bad measurement: the warning path */
    bad |= fmi3SetFloat64(c, in, 4, y, 4) > fmi3Warning;
    bad |= fmi3DoStep(c, t, ts, fmi3True, &a, &b, &e, &last) > fmi3Warning;
    bad |= fmi3GetFloat64(c, out, 2, u, 2) > fmi3Warning;
    y[0] = h1;
  }
  counting = 0;
  fmi3FreeInstance(c);
  printf("allocations at instantiation: %ld\n", at_instantiation);
  printf("allocations while stepping: %ld, status %s, u = %g %g\n", count, bad ? "bad" : "ok",
         u[0], u[1]);
  return 0;
}
