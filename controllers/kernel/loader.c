/* loader.c: the numbers of a data-mode build, read at run time
 * (controllers/kernel/constants.py).
 *
 * Joined last, after the table GK_DATA (GK_DATA_COUNT entries: name, address, size, int or
 * double), GK_DATA_KEY (the layout's key) and GK_DATA_VALUES (the number of values).
 * PFX(load_data) checks a data file, given in memory, against the table -- its format, its
 * layout, its size, its checksum (a damaged file), then every value against its constant's
 * plausible range (an absurd value) -- and copies its values into the declared constants.
 * The library holds one set of numbers: a second load must bring the same numbers (the
 * instances of one controller FMU share its resources), a different set is refused, and
 * loads from several threads are serialised. Nothing is written unless the whole file is
 * valid.
 */
#include <limits.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>

#define GK_DATA_MAGIC "GKDATA02"
/* magic (8), layout key (16), number of values (uint64), CRC-32 of the rest (uint64) */
#define GK_DATA_HEADER 40
#define GK_DATA_RANGE 3 /* per constant: low, high, 1.0 where +-inf is allowed */

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

/* CRC-32 (zlib's: reflected, polynomial 0xEDB88320) of p[0 .. n) */
static uint32_t gk_crc32(const unsigned char *p, size_t n) {
  uint32_t c = 0xFFFFFFFFu;
  for (size_t i = 0; i < n; i++) {
    c ^= p[i];
    for (int k = 0; k < 8; k++) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
  }
  return ~c;
}

/* Why the values v (after the ranges r) cannot be stored, written to msg; NULL when they
 * can: a range that is not one, NaN, an infinity where none is allowed, a non-integer for
 * an int, a finite value outside its constant's plausible range. */
static const char *gk_data_invalid(const unsigned char *r, const unsigned char *v, char *msg,
                                   size_t n) {
  for (int e = 0; e < GK_DATA_COUNT; e++, r += 8 * GK_DATA_RANGE) {
    const gk_datum *d = &GK_DATA[e];
    const double lo = gk_le_double(r), hi = gk_le_double(r + 8), inf_ok = gk_le_double(r + 16);
    if (!(lo <= hi) || (inf_ok != 0.0 && inf_ok != 1.0)) {
      snprintf(msg, n, "the plausible range of %s is not one ([%g, %g])", d->name, lo, hi);
      return msg;
    }
    for (long i = 0; i < d->size; i++, v += 8) {
      const double x = gk_le_double(v);
      if (isnan(x))
        snprintf(msg, n, "%s[%ld] is NaN", d->name, i);
      else if (isinf(x) && (d->is_int || inf_ok != 1.0))
        snprintf(msg, n, "%s[%ld] is infinite", d->name, i);
      else if (d->is_int && !gk_is_int(x))
        snprintf(msg, n, "%s[%ld] = %.17g is not an integer", d->name, i, x);
      else if (isfinite(x) && (x < lo || x > hi))
        snprintf(msg, n, "%s[%ld] = %.17g is outside its plausible range [%g, %g]", d->name,
                 i, x, lo, hi);
      else
        continue;
      return msg;
    }
  }
  return NULL;
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
  if (!bytes || size < GK_DATA_HEADER || memcmp(bytes, GK_DATA_MAGIC, 7) != 0) {
    snprintf(msg, n, "not a controller data file (it starts with %s)", GK_DATA_MAGIC);
    return msg;
  }
  if (memcmp(bytes, GK_DATA_MAGIC, 8) != 0) {
    snprintf(msg, n, "its format %.8s is not this library's %s (export the FMU again)",
             (const char *)bytes, GK_DATA_MAGIC);
    return msg;
  }
  if (memcmp(bytes + 8, GK_DATA_KEY, 16) != 0) {
    snprintf(msg, n, "its layout %.16s is not this library's %s (exported for other "
                     "dimensions)", (const char *)bytes + 8, GK_DATA_KEY);
    return msg;
  }
  const size_t expected = GK_DATA_HEADER + 8 * (size_t)(GK_DATA_RANGE * GK_DATA_COUNT +
                                                        GK_DATA_VALUES);
  const uint64_t count = gk_le_u64(bytes + 24);
  if (count != GK_DATA_VALUES || size != expected) {
    snprintf(msg, n, "%zu bytes, expected %d values (%zu bytes)", size, GK_DATA_VALUES,
             expected);
    return msg;
  }
  const uint64_t stored = gk_le_u64(bytes + 32);
  const uint32_t crc = gk_crc32(bytes + GK_DATA_HEADER, size - GK_DATA_HEADER);
  if (stored != (uint64_t)crc) {
    snprintf(msg, n, "damaged: its checksum %08llx does not match its contents (%08lx)",
             (unsigned long long)stored, (unsigned long)crc);
    return msg;
  }
  const unsigned char *ranges = bytes + GK_DATA_HEADER;
  const unsigned char *values = ranges + 8 * GK_DATA_RANGE * GK_DATA_COUNT;
  if (gk_data_invalid(ranges, values, msg, n)) return msg;
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
