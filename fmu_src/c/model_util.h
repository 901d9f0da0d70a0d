/*
 * model_util.h - small helpers shared by the C model files (C99, libc and libm), so that their
 * arithmetic and their messages are those of the Python runtimes they mirror.
 */
#ifndef LATOBS_MODEL_UTIL_H
#define LATOBS_MODEL_UTIL_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* first + sum_j a[j] b[j], added left to right: the Python runtimes' sum(map(mul, a, b)) (first = 0)
 * and sum([a * b ...], first), to the last bit */
static inline double dot_from(double first, const double *a, const double *b, int n)
{
    double acc = first;
    for (int j = 0; j < n; j++) acc += a[j] * b[j];
    return acc;
}

/* x as Python's repr() writes it (the shortest digits that read back as x; fixed notation for
 * exponents -4..15: "100.0", "0.1", "1e-05"), so that the warnings read like the Python runtime's */
static inline const char *py_repr(double x, char buf[32])
{
    int digits = 1;
    if (!isfinite(x)) {
        snprintf(buf, 32, "%s", x != x ? "nan" : x > 0 ? "inf" : "-inf");
        return buf;
    }
    for (; digits < 17; digits++) {
        snprintf(buf, 32, "%.*e", digits - 1, x);
        if (strtod(buf, NULL) == x) break;
    }
    snprintf(buf, 32, "%.*e", digits - 1, x);
    int e = atoi(strchr(buf, 'e') + 1), decimals = digits - 1 - e;
    if (e < -4 || e >= 16) return buf;
    snprintf(buf, 32, "%.*f", decimals > 0 ? decimals : 0, x);
    if (decimals <= 0) strcat(buf, ".0");
    return buf;
}

#endif
