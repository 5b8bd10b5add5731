//! The path kernel's per-vertex arithmetic (`shade8`), its rough conductors' and rough
//! plastics' lanes (`conductor8`, `plastic8`, and their GGX copies), the light walks' Lambertian step
//! (`path::step8`) and their emission samples (`light::emit8`) compile to eight-lane vector
//! code in the shipped binary. Whether LLVM vectorises such a loop has flipped silently with
//! unrelated edits (an `Option` field added to a struct it reads, a `bool` read under a
//! condition), and the scalar loop cost 1.2-1.5x on every kernel scene with the same image:
//! no other test sees it. Reads the release binary's disassembly with `objdump` (binutils);
//! skipped in debug builds, which do not vectorise, and off x86_64.

#[cfg(all(target_arch = "x86_64", not(debug_assertions)))]
#[test]
fn shade8_is_vector_code() {
    use std::process::Command;
    let exe = env!("CARGO_BIN_EXE_svetlo");
    let nm = match Command::new("nm").arg(exe).output() {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
        _ => {
            assert!(std::env::var_os("SVETLO_CODEGEN_TEST").is_none(), "nm (binutils) is missing");
            eprintln!("skipped: nm (binutils) is missing");
            return;
        }
    };
    // Each copy with the fewest packed operations its vector code has.
    for (copy, least) in [
        ("shade8_avx2", 100),
        ("shade8_avx512", 100),
        ("conductor8_avx2", 100),
        ("conductor8_avx512", 100),
        ("plastic8_avx2", 100),
        ("plastic8_avx512", 100),
        ("conductor_ggx8_avx2", 100),
        ("conductor_ggx8_avx512", 100),
        ("plastic_ggx8_avx2", 100),
        ("plastic_ggx8_avx512", 100),
        ("dielectric8_avx2", 100),
        ("dielectric8_avx512", 100),
        ("step8_avx2", 100),
        ("step8_avx512", 100),
        ("emit8_avx2", 50),
        ("emit8_avx512", 50),
    ] {
        // The mangled name of the copy (one function each: `#[inline(never)]`).
        let symbol = nm
            .lines()
            .filter_map(|l| l.split_whitespace().nth(2))
            .find(|s| s.contains(copy) && !s.contains("closure"))
            .unwrap_or_else(|| panic!("no symbol {copy} in {exe}: was it inlined or renamed?"));
        let out = Command::new("objdump").args(["-d", "--no-show-raw-insn", &format!("--disassemble={symbol}"), exe]).output().expect("objdump runs");
        assert!(out.status.success(), "objdump failed on {symbol}");
        let text = String::from_utf8_lossy(&out.stdout);
        // Float arithmetic, packed (`..ps`) and scalar (`..ss`).
        let (mut packed, mut scalar) = (0, 0);
        for mnemonic in text.lines().filter_map(|l| l.split('\t').nth(1)).map(|m| m.split_whitespace().next().unwrap_or("")) {
            let arith = ["vmul", "vadd", "vsub", "vdiv", "vfmadd", "vfnmadd", "vfmsub", "vsqrt", "vmin", "vmax"].iter().any(|p| mnemonic.starts_with(p));
            if arith && mnemonic.ends_with("ps") {
                packed += 1;
            } else if arith && mnemonic.ends_with("ss") {
                scalar += 1;
            }
        }
        // Vector code: ~200-250 packed operations in `shade8`, ~600 in `conductor8` (the
        // rough conductors' lanes; its ~14 scalar ones test the numbers libm's expf is called
        // for), ~750 in `plastic8` (the rough plastics' lanes), ~140 in `step8`, ~85 in
        // `emit8`, and few scalar (the scalar loop had one `..ss` per lane and operation, and
        // a branch per lane).
        assert!(packed >= least && scalar * 8 <= packed, "{copy}: {packed} packed and {scalar} scalar float operations: its loop is no longer vector code");
    }
}
