/* loader.c: the numbers of a data-mode build, read at run time
 * (controllers/kernel/constants.py).
 *
 * Joined last, after the table GK_DATA (GK_DATA_COUNT entries: name, address, size, int or
 * double), GK_DATA_KEY (the layout's key) and GK_DATA_VALUES (the number of values).
 * PFX(load_data) checks a data file, given in memory, against the table and copies its
 * values into the declared constants. The library holds one set of numbers: a second load
 * must bring the same numbers (the instances of one controller FMU share its resources), a
 * different set is refused, and loads from several threads are serialised. Nothing is
 * written unless the whole file is valid.
 */
#include <limits.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>

#define GK_DATA_MAGIC "GKDATA01"
#define GK_DATA_HEADER 32 /* magic (8), layout key (16), number of values (uint64) */

static pthread_mutex_t gk_data_lock = PTHREAD_MUTEX_INITIALIZER;
static int gk_data_loaded = 0;

static int gk_data_ready(void) {
  pthread_mutex_lock(&gk_data_lock);
  const int ready = gk_data_loaded;
  pthread_mutex_unlock(&gk_data_lock);
  return ready;
}

static uint64_t gk_le_u64(const unsigned char *b) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; i--) v = (v << 8) | b[i];
  return v;
}

static double gk_le_double(const unsigned char *b) {
  const uint64_t v = gk_le_u64(b);
  double d;
  memcpy(&d, &v, sizeof d);
  return d;
}

static int gk_is_int(double x) { return x >= INT_MIN && x <= INT_MAX && x == floor(x); }

/* The values' first entry that cannot be stored (NaN, or a non-integer for an int), or -1;
 * its index in *at. */
static int gk_data_invalid(const unsigned char *v, long *at) {
  for (int e = 0; e < GK_DATA_COUNT; e++)
    for (long i = 0; i < GK_DATA[e].size; i++, v += 8) {
      const double x = gk_le_double(v);
      if (GK_DATA[e].is_int ? !gk_is_int(x) : isnan(x)) {
        *at = i;
        return e;
      }
    }
  return -1;
}

/* Store the values (store = 1), or find the first entry they differ from those stored
 * (store = 0; -1: none). */
static int gk_data_copy(const unsigned char *v, int store) {
  for (int e = 0; e < GK_DATA_COUNT; e++) {
    const gk_datum *d = &GK_DATA[e];
    for (long i = 0; i < d->size; i++, v += 8) {
      const double x = gk_le_double(v);
      if (d->is_int) {
        int *p = (int *)d->at + i;
        if (store) *p = (int)x;
        else if (*p != (int)x) return e;
      } else {
        double *p = (double *)d->at + i;
        if (store) *p = x;
        else if (memcmp(p, &x, sizeof x) != 0) return e;
      }
    }
  }
  return -1;
}

/* Load the data file bytes[0 .. size) (controllers/kernel/constants.py): NULL, or the reason
 * it is refused, written to msg (n chars). */
EXPORT const char *PFX(load_data)(const unsigned char *bytes, size_t size, char *msg,
                                  size_t n) {
  if (!bytes || size < GK_DATA_HEADER || memcmp(bytes, GK_DATA_MAGIC, 8) != 0) {
    snprintf(msg, n, "not a controller data file (it starts with %s)", GK_DATA_MAGIC);
    return msg;
  }
  if (memcmp(bytes + 8, GK_DATA_KEY, 16) != 0) {
    snprintf(msg, n, "its layout %.16s is not this library's %s (exported for other "
                     "dimensions)", (const char *)bytes + 8, GK_DATA_KEY);
    return msg;
  }
  const uint64_t count = gk_le_u64(bytes + 24);
  if (count != GK_DATA_VALUES || size != GK_DATA_HEADER + 8 * (size_t)count) {
    snprintf(msg, n, "%zu bytes, expected %d values (%d bytes)", size, GK_DATA_VALUES,
             GK_DATA_HEADER + 8 * GK_DATA_VALUES);
    return msg;
  }
  const unsigned char *values = bytes + GK_DATA_HEADER;
  long at = 0;
  const int bad = gk_data_invalid(values, &at);
  if (bad >= 0) {
    snprintf(msg, n, "%s[%ld] is %s", GK_DATA[bad].name, at,
             GK_DATA[bad].is_int ? "not an integer" : "NaN");
    return msg;
  }
  const char *why = 0;
  pthread_mutex_lock(&gk_data_lock);
  if (!gk_data_loaded) {
    gk_data_copy(values, 1);
    gk_data_loaded = 1;
  } else {
    const int e = gk_data_copy(values, 0);
    if (e >= 0) {
      snprintf(msg, n, "its %s differs from the numbers this library already holds (one "
                       "design per loaded library)", GK_DATA[e].name);
      why = msg;
    }
  }
  pthread_mutex_unlock(&gk_data_lock);
  return why;
}
