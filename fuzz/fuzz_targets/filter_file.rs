//! The filter-file loader on arbitrary bytes. The format ends in an FNV-1a checksum of the rest,
//! which random bytes almost never match; so every input is tried twice: as given, and with the
//! correct checksum appended, which lets the fuzzer reach the header and body validation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use unshear::filters::EyeFilters;

/// FNV-1a 64, as the file format defines it (src/filters/file.rs).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fuzz_target!(|data: &[u8]| {
    let _ = EyeFilters::from_bytes(data);
    let mut sealed = data.to_vec();
    sealed.extend_from_slice(&fnv1a(data).to_le_bytes());
    if let Ok(filters) = EyeFilters::from_bytes(&sealed) {
        // What loads must write back to the same bytes.
        assert_eq!(filters.to_bytes(), sealed);
    }
});
