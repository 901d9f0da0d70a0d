/*
 * fp_contract.h - the floating-point contract of the native FMUs, in the sources themselves:
 * no contraction (no fused multiply-add, FMA) anywhere.
 *
 * The C runtimes mirror the Python runtimes operation by operation and every native FMU must give
 * the same numbers on every platform and with every compiler that rebuilds it from sources/. A
 * compiler that contracts a*b + c into one FMA rounds once instead of twice: the last bit changes,
 * and through the observers' feedback the difference grows. Where FMA exists (aarch64 always;
 * x86-64 with -mfma, -march=native, -march=x86-64-v3, /arch:AVX2) the defaults contract: GCC in its
 * GNU modes (the default, and what CMake's C_STANDARD gives) fuses even across statements, clang
 * and MSVC before Visual Studio 2022 fuse within an expression. latobs's own build passes
 * -ffp-contract=off, but importers that recompile the FMU (fmpy's build_platform_binary, FMI Kit
 * for Simulink, dSPACE, a user's MSVC project) drop compiler options; so the contract is stated
 * here, in the header every C file includes before any code of its own (through model.h):
 *
 *   GCC      ignores '#pragma STDC FP_CONTRACT' (and warns under -Wall); it honours
 *            '#pragma GCC optimize', which applies its options to every function defined after
 *            it. -ffp-contract=off is not enough on its own: GCC 12 at -O3 with FMA still fuses
 *            an SLP-vectorised pair a*b - c, a*d + c into one vfmaddsub (CarPlant's wheel loads;
 *            measured, also with -ffp-contract=off or -std=c99 on the command line), so the SLP
 *            vectoriser is off as well. Verified with GCC 12.2 on x86-64, -O1 to -O3, -mfma /
 *            -march=native / x86-64-v3, GNU and ISO modes, _FORTIFY_SOURCE: no FMA instruction
 *            in any FMU.
 *   clang    (also clang-cl, zig cc, Apple clang) honours the C99 pragma (C99 7.12.2); verified
 *            with zig cc (clang 22) for x86-64 -O3 -mfma, aarch64-linux and aarch64-macos.
 *   MSVC     '#pragma fp_contract (off)' (the default since Visual Studio 2022 17.0; earlier
 *            versions contract with /arch:AVX2 unless told); read in Microsoft's documentation,
 *            not verified here.
 * Fast-math options (-ffast-math, -Ofast, /fp:fast) reorder sums and are outside this contract.
 */
#ifndef LATOBS_FP_CONTRACT_H
#define LATOBS_FP_CONTRACT_H

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize ("fp-contract=off", "no-tree-slp-vectorize")
#elif defined(_MSC_VER) && !defined(__clang__)
#pragma fp_contract (off)
#else
#pragma STDC FP_CONTRACT OFF
#endif

#endif
