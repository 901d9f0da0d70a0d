/*
 * glibc_compat.h - the old-glibc baseline of the native FMUs (included first by the build: -include).
 *
 * glibc 2.29 gave exp, exp2, log, log2 and pow new symbol versions (new implementations; old and
 * new are both accurate to within an ulp, and may differ in the last bit); a library linked
 * against a newer glibc then needs GLIBC_2.29 at load time. Binding them to their original versions keeps every
 * symbol of the shared object at GLIBC_2.17 or older (tests/cbackend/test_c_backend.py checks it), so the
 * FMU loads on old enterprise Linux distributions too. Linux x86-64 with glibc only; elsewhere
 * this header does nothing (aarch64's oldest glibc version is 2.17 anyway).
 */
#if defined(__linux__) && defined(__x86_64__) && !defined(LATOBS_NO_GLIBC_COMPAT)
#include <features.h> /* defines __GLIBC__ on glibc (musl has the header too, without it) */
#endif
#if defined(__linux__) && defined(__x86_64__) && defined(__GLIBC__) && !defined(LATOBS_NO_GLIBC_COMPAT)
__asm__(".symver exp,exp@GLIBC_2.2.5");
__asm__(".symver exp2,exp2@GLIBC_2.2.5");
__asm__(".symver log,log@GLIBC_2.2.5");
__asm__(".symver log2,log2@GLIBC_2.2.5");
__asm__(".symver pow,pow@GLIBC_2.2.5");
#endif
