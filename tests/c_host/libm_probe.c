/*
 * libm_probe.c - which C math functions give other bits on another platform's C library.
 *
 * For each libm function the native FMUs call, evaluates it on 100000 arguments spread over
 * the magnitudes an FMU meets (1e-4 ... 1e2, both signs; a fixed xorshift sequence, the same
 * on every platform) and prints "name hash": an FNV-1a hash of the results' bits. Compiled for
 * each platform and run there (Wine, qemu), equal hashes mean the same bits on every argument.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

static uint64_t state = 88172645463325252u;

static double uniform(double lo, double hi)
{
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return lo + (hi - lo) * (double)(state >> 11) / 9007199254740992.0;
}

int main(void)
{
    static const char *names[] = {"sin", "cos", "tan", "atan", "atan2", "exp", "expm1", "log2", "pow", "sqrt"};
    static const double scale[] = {1e-4, 1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2};
    for (int f = 0; f < 10; f++) {
        uint64_t hash = 1469598103934665603u, bits;
        for (int k = 0; k < 100000; k++) {
            double x = uniform(-4.0, 4.0) * scale[k % 7], y = uniform(-3.0, 3.0), r;
            switch (f) {
            case 0: r = sin(x); break;
            case 1: r = cos(x); break;
            case 2: r = tan(x); break;
            case 3: r = atan(x); break;
            case 4: r = atan2(x, y); break;
            case 5: r = exp(x); break;
            case 6: r = expm1(x); break;
            case 7: r = log2(fabs(x)); break;
            case 8: r = pow(fabs(x), y); break;
            default: r = sqrt(fabs(x)); break;
            }
            memcpy(&bits, &r, sizeof bits);
            hash = (hash ^ bits) * 1099511628211u;
        }
        printf("%s %016llx\n", names[f], (unsigned long long)hash);
    }
    return 0;
}
