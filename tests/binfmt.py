"""Pure-Python readers of the three binary formats in an FMU (tests only; no objdump/readelf/otool
needed): what a Windows DLL exports and imports (PE/COFF), what an ELF shared object needs and
exports (dynamic section, symbol versions), and what a Mach-O library is (universal slices,
file type, exported symbols, install name, dependencies, minimum OS version).

Only the parts the tests read, following the formats' specifications: Microsoft's "PE Format",
the System V gABI with the GNU symbol-versioning extension, Apple's <mach-o/loader.h>,
<mach-o/nlist.h> and the dyld export trie.
"""
from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from pathlib import Path


def fmi2_functions(header: Path) -> list[str]:
    """Every function an FMI 2.0 shared library exports, as ``fmi2Functions.h`` declares them
    (``FMI2_Export fmi2XxxTYPE fmi2Xxx;``)."""
    names = re.findall(r"FMI2_Export\s+fmi2\w+TYPE\s+(fmi2\w+)\s*;", header.read_text(encoding="utf-8"))
    if len(names) < 40:
        raise ValueError(f"{header}: found only {len(names)} fmi2 function declarations")
    return names


def _cstr(raw: bytes, offset: int) -> str:
    end = raw.index(b"\0", offset)
    return raw[offset:end].decode("ascii", errors="replace")


# ---------------------------------------------------------------------------------------------
# PE/COFF (Windows DLL)
# ---------------------------------------------------------------------------------------------
@dataclass
class PeInfo:
    machine: int                     # 0x8664: x86-64
    is_dll: bool
    dll_name: str                    # the export directory's own name
    exports: list[str]
    imports: dict[str, list[str]]    # DLL -> functions (by name; ordinals as "#n")
    delay_imports: list[str] = field(default_factory=list)


def read_pe(raw: bytes) -> PeInfo:
    if raw[:2] != b"MZ":
        raise ValueError("not a PE file (no MZ header)")
    pe = struct.unpack_from("<I", raw, 0x3C)[0]
    if raw[pe:pe + 4] != b"PE\0\0":
        raise ValueError("not a PE file (no PE signature)")
    machine, nsections, _, _, _, opt_size, characteristics = struct.unpack_from("<HHIIIHH", raw, pe + 4)
    opt = pe + 24
    magic = struct.unpack_from("<H", raw, opt)[0]
    if magic != 0x20B:
        raise ValueError(f"not a PE32+ file (optional header magic {magic:#x})")
    ndirs = struct.unpack_from("<I", raw, opt + 108)[0]
    dirs = [struct.unpack_from("<II", raw, opt + 112 + 8 * k) for k in range(ndirs)]
    sections = []
    for k in range(nsections):
        s = opt + opt_size + 40 * k
        vsize, vaddr, rsize, rptr = struct.unpack_from("<IIII", raw, s + 8)
        sections.append((vaddr, max(vsize, rsize), rptr))

    def off(rva: int) -> int:
        for vaddr, size, rptr in sections:
            if vaddr <= rva < vaddr + size:
                return rva - vaddr + rptr
        raise ValueError(f"RVA {rva:#x} is in no section")

    exports, dll_name = [], ""
    if ndirs > 0 and dirs[0][0]:
        e = off(dirs[0][0])
        # export directory: name RVA at 12, number of name pointers at 24, name pointer table RVA at 32
        name_rva, n_names, names_rva = (struct.unpack_from("<I", raw, e + k)[0] for k in (12, 24, 32))
        dll_name = _cstr(raw, off(name_rva))
        for k in range(n_names):
            exports.append(_cstr(raw, off(struct.unpack_from("<I", raw, off(names_rva) + 4 * k)[0])))
    imports: dict[str, list[str]] = {}
    if ndirs > 1 and dirs[1][0]:
        d = off(dirs[1][0])
        while True:
            lookup, _, _, name_rva, thunks = struct.unpack_from("<IIIII", raw, d)
            if not (lookup or name_rva or thunks):
                break
            funcs = []
            t = off(lookup or thunks)
            while True:
                entry = struct.unpack_from("<Q", raw, t)[0]
                if entry == 0:
                    break
                funcs.append(f"#{entry & 0xFFFF}" if entry >> 63 else _cstr(raw, off(entry & 0x7FFFFFFF) + 2))
                t += 8
            imports[_cstr(raw, off(name_rva))] = funcs
            d += 20
    delay = []
    if ndirs > 13 and dirs[13][0]:
        d = off(dirs[13][0])
        while True:
            name_rva = struct.unpack_from("<I", raw, d + 4)[0]
            if not name_rva:
                break
            delay.append(_cstr(raw, off(name_rva)))
            d += 32
    return PeInfo(machine, bool(characteristics & 0x2000), dll_name, exports, imports, delay)


# ---------------------------------------------------------------------------------------------
# ELF (Linux shared object, 64-bit little-endian)
# ---------------------------------------------------------------------------------------------
@dataclass
class ElfInfo:
    machine: int                     # 62: x86-64, 183: aarch64
    needed: list[str]                # DT_NEEDED
    soname: str | None
    exports: list[str]               # global/weak defined dynamic symbols
    versions: dict[str, list[str]]   # needed library -> symbol versions needed from it (GLIBC_2.17, ...)


def read_elf(raw: bytes) -> ElfInfo:
    if raw[:4] != b"\x7fELF" or raw[4] != 2 or raw[5] != 1:
        raise ValueError("not a 64-bit little-endian ELF file")
    e_type, machine = struct.unpack_from("<HH", raw, 16)
    shoff = struct.unpack_from("<Q", raw, 0x28)[0]
    shentsize, shnum = struct.unpack_from("<HH", raw, 0x3A)
    secs = []
    for k in range(shnum):
        name, stype, _, _, offset, size, link, info, _, entsize = struct.unpack_from("<IIQQQQIIQQ", raw,
                                                                                    shoff + k * shentsize)
        secs.append((stype, offset, size, link, info, entsize))
    SHT_DYNSYM, SHT_DYNAMIC, SHT_VERNEED = 11, 6, 0x6FFFFFFE
    needed, soname, exports, versions = [], None, [], {}
    for stype, offset, size, link, info, entsize in secs:
        strtab = secs[link][1]
        if stype == SHT_DYNAMIC:
            for k in range(size // 16):
                tag, val = struct.unpack_from("<qQ", raw, offset + 16 * k)
                if tag == 1:
                    needed.append(_cstr(raw, strtab + val))
                elif tag == 14:
                    soname = _cstr(raw, strtab + val)
        elif stype == SHT_DYNSYM:
            for k in range(size // entsize):
                st_name, st_info, _, st_shndx = struct.unpack_from("<IBBH", raw, offset + entsize * k)
                if st_shndx != 0 and (st_info >> 4) in (1, 2) and st_name:   # defined, GLOBAL or WEAK
                    exports.append(_cstr(raw, strtab + st_name))
        elif stype == SHT_VERNEED:
            at = offset
            for _ in range(info):
                _, cnt, file_, aux, nxt = struct.unpack_from("<HHIII", raw, at)
                lib, names, a = _cstr(raw, strtab + file_), [], at + aux
                for _ in range(cnt):
                    _, _, _, vname, anext = struct.unpack_from("<IHHII", raw, a)
                    names.append(_cstr(raw, strtab + vname))
                    a += anext
                versions[lib] = names
                if not nxt:
                    break
                at += nxt
    return ElfInfo(machine, needed, soname, exports, versions)


# ---------------------------------------------------------------------------------------------
# Mach-O (universal and thin 64-bit)
# ---------------------------------------------------------------------------------------------
CPU_X86_64, CPU_ARM64 = 0x01000007, 0x0100000C
MH_DYLIB = 6
LC_SYMTAB, LC_ID_DYLIB, LC_LOAD_DYLIB, LC_DYLD_INFO_ONLY = 0x2, 0xD, 0xC, 0x80000022
LC_BUILD_VERSION, LC_VERSION_MIN_MACOSX, LC_DYLD_EXPORTS_TRIE = 0x32, 0x24, 0x80000033
LC_CODE_SIGNATURE = 0x1D


@dataclass
class MachOInfo:
    cputype: int
    filetype: int
    install_name: str | None
    dylibs: list[str]                # LC_LOAD_DYLIB
    exports: list[str]               # the export trie's symbols (C names: without the leading '_')
    symtab_exports: list[str]        # LC_SYMTAB's external defined symbols (the same, if present)
    min_os: tuple[int, int, int] | None
    signature: tuple[int, int] | None  # LC_CODE_SIGNATURE (offset, size) in the file, if any


def _uleb(raw: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        b = raw[at]
        at += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if b < 0x80:
            return value, at


def _trie(raw: bytes, start: int, node: int, prefix: str, out: list[str], depth: int = 0) -> None:
    if depth > 256:
        raise ValueError("export trie too deep")
    at = start + node
    size, at = _uleb(raw, at)
    if size:
        out.append(prefix)
    at += size                       # the terminal's flags and address, then the children
    count, at = raw[at], at + 1
    for _ in range(count):
        end = raw.index(b"\0", at)
        edge = raw[at:end].decode("ascii")
        child, at = _uleb(raw, end + 1)
        _trie(raw, start, child, prefix + edge, out, depth + 1)


def read_macho(raw: bytes) -> MachOInfo:
    magic, cputype, _, filetype, ncmds, _, _, _ = struct.unpack_from("<IiIIIIII", raw, 0)
    if magic != 0xFEEDFACF:
        raise ValueError("not a thin 64-bit little-endian Mach-O file")
    at, install, dylibs, exports, symtab, min_os, signature = 32, None, [], [], [], None, None
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", raw, at)
        if cmd in (LC_ID_DYLIB, LC_LOAD_DYLIB):
            name = _cstr(raw, at + struct.unpack_from("<I", raw, at + 8)[0])
            if cmd == LC_ID_DYLIB:
                install = name
            else:
                dylibs.append(name)
        elif cmd == LC_SYMTAB:
            symoff, nsyms, stroff, _ = struct.unpack_from("<IIII", raw, at + 8)
            for k in range(nsyms):
                strx, ntype, _, _, _ = struct.unpack_from("<IBBHQ", raw, symoff + 16 * k)
                if ntype & 0x01 and (ntype & 0x0E) == 0x0E and not ntype & 0xE0:   # N_EXT, N_SECT, no stab
                    symtab.append(_cstr(raw, stroff + strx).removeprefix("_"))
        elif cmd in (LC_DYLD_INFO_ONLY, LC_DYLD_EXPORTS_TRIE):
            off, sz = (struct.unpack_from("<II", raw, at + 40) if cmd == LC_DYLD_INFO_ONLY
                       else struct.unpack_from("<II", raw, at + 8))
            if sz:
                names: list[str] = []
                _trie(raw, off, 0, "", names)
                exports = [n.removeprefix("_") for n in names]
        elif cmd in (LC_BUILD_VERSION, LC_VERSION_MIN_MACOSX):
            v = struct.unpack_from("<I", raw, at + (12 if cmd == LC_BUILD_VERSION else 8))[0]
            min_os = (v >> 16, (v >> 8) & 0xFF, v & 0xFF)
        elif cmd == LC_CODE_SIGNATURE:
            signature = struct.unpack_from("<II", raw, at + 8)
        at += size
    return MachOInfo(cputype, filetype, install, dylibs, exports, symtab, min_os, signature)


def code_signature_pages(raw: bytes) -> tuple[int, list[int]]:
    """Check a thin Mach-O file's code signature (an ad-hoc one, as Apple silicon requires of
    every library it loads): (pages hashed, [pages whose SHA-256 differs from the code
    directory's]). ValueError without a signature or with a code directory it cannot read."""
    import hashlib

    sig = read_macho(raw).signature
    if sig is None:
        raise ValueError("no LC_CODE_SIGNATURE")
    base = sig[0]
    magic, _, count = struct.unpack_from(">III", raw, base)
    if magic != 0xFADE0CC0:
        raise ValueError(f"not an embedded signature (magic {magic:#x})")
    for k in range(count):
        _, offset = struct.unpack_from(">II", raw, base + 12 + 8 * k)
        cd = base + offset
        if struct.unpack_from(">I", raw, cd)[0] != 0xFADE0C02:          # CodeDirectory
            continue
        hash_offset, _, _, n_code, code_limit = struct.unpack_from(">IIIII", raw, cd + 16)
        hash_size, hash_type, _, page_log2 = struct.unpack_from(">BBBB", raw, cd + 36)
        if hash_type != 2 or hash_size != 32:
            raise ValueError(f"code directory hash type {hash_type} is not SHA-256")
        page = 1 << page_log2
        bad = [i for i in range(n_code)
               if hashlib.sha256(raw[i * page:min((i + 1) * page, code_limit)]).digest()
               != raw[cd + hash_offset + 32 * i: cd + hash_offset + 32 * (i + 1)]]
        return n_code, bad
    raise ValueError("no code directory in the signature")
