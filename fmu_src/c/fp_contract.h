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
 *            '#pragma GCC optimize', which applies -ffp-contract=off to every function defined
 *            after it (verified with GCC 12, -O2/-O3 -mfma, GNU and ISO modes). An ISO mode
 *            (-std=c99, not gnu99) or -ffp-contract=off on the command line does the same.
 *   clang    (also clang-cl, zig cc, Apple clang, icx) honours the C99 pragma (C99 7.12.2).
 *   MSVC     '#pragma fp_contract (off)' (the default since Visual Studio 2022 17.0; earlier
 *            versions contract with /arch:AVX2 unless told).
 */
#ifndef LATOBS_FP_CONTRACT_H
#define LATOBS_FP_CONTRACT_H

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize ("fp-contract=off")
#elif defined(_MSC_VER) && !defined(__clang__)
#pragma fp_contract (off)
#else
#pragma STDC FP_CONTRACT OFF
#endif

#endif
