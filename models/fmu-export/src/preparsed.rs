//! Tables a model parses from a bundled CSV resource, parsed once at build time.
//!
//! A model's build script runs the model's own parser on its bundled file and stores the
//! numbers with a digest of the file's bytes ([`encode`]); the model embeds that blob. At
//! run time it reads the resource as before and, when the bytes still have the digest the
//! blob was made from, takes the numbers from the blob ([`decode`]) instead of parsing them
//! again: the same parser made them, so they are the same bits. A resource that was
//! changed (another digest) is parsed as it is. Start-up of a process then costs a read
//! and a digest of the file, not a parse (the bundled track is 85,000 numbers).

const MAGIC: &[u8; 8] = b"TBSIDE01"; // the blob's magic (its first name, kept: blobs stay the same bytes)

/// A 64-bit digest of `bytes` (8 bytes at a time, multiply-rotate mixing, the length
/// folded in): a changed resource gets another digest with overwhelming probability.
pub fn digest(bytes: &[u8]) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut h: u64 = 0x243F_6A88_85A3_08D3 ^ bytes.len() as u64;
    let mut chunks = bytes.chunks_exact(8);
    for c in &mut chunks {
        let w = u64::from_le_bytes(c.try_into().expect("8 bytes"));
        h = (h ^ w).wrapping_mul(K).rotate_left(29);
    }
    let mut tail = [0u8; 8];
    tail[..chunks.remainder().len()].copy_from_slice(chunks.remainder());
    h = (h ^ u64::from_le_bytes(tail))
        .wrapping_mul(K)
        .rotate_left(29);
    // A final avalanche, so that every input bit reaches every output bit.
    h ^= h >> 32;
    h = h.wrapping_mul(K);
    h ^ (h >> 29)
}

/// The blob of a table of `columns` numbers per row made from a file with digest `digest`.
pub fn encode(digest: u64, columns: usize, values: &[f64]) -> Vec<u8> {
    let mut out = Vec::with_capacity(32 + 8 * values.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&digest.to_le_bytes());
    out.extend_from_slice(&(columns as u64).to_le_bytes());
    out.extend_from_slice(&(values.len() as u64).to_le_bytes());
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// The numbers of `blob` when it was made from a file with `digest` and `columns` numbers
/// per row; None otherwise (an empty blob, another file, another layout).
pub fn decode(blob: &[u8], digest: u64, columns: usize) -> Option<Vec<f64>> {
    let word = |k: usize| -> Option<u64> {
        Some(u64::from_le_bytes(blob.get(k..k + 8)?.try_into().ok()?))
    };
    if blob.get(..8)? != MAGIC || word(8)? != digest || word(16)? != columns as u64 {
        return None;
    }
    let n = usize::try_from(word(24)?).ok()?;
    let data = blob.get(32..)?;
    if columns == 0 || !n.is_multiple_of(columns) || data.len() != n.checked_mul(8)? {
        return None;
    }
    Some(
        data.chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect(),
    )
}

/// For a model's build script: parses the bundled file `csv` with the model's own parser
/// (`parse`: the rows as `columns` numbers each) and writes the blob to `$OUT_DIR/out`. The
/// blob is empty when the file does not parse: the model then parses it at run time and
/// reports the error there.
pub fn build(csv: &str, out: &str, columns: usize, parse: impl FnOnce(&str) -> Option<Vec<f64>>) {
    println!("cargo:rerun-if-changed={csv}");
    let dir = std::path::PathBuf::from(std::env::var("OUT_DIR").expect("set by cargo"));
    let blob = std::fs::read_to_string(csv)
        .ok()
        .and_then(|text| Some(encode(digest(text.as_bytes()), columns, &parse(&text)?)))
        .unwrap_or_default();
    std::fs::write(dir.join(out), blob).expect("OUT_DIR is writable");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_refusals() {
        let values = [0.0, 1.5, -2.25, f64::MIN_POSITIVE, 1e300, 7.0];
        let d = digest(b"s,v\n0,1.5\n");
        let blob = encode(d, 2, &values);
        let back = decode(&blob, d, 2).unwrap();
        assert_eq!(
            back.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            values.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        assert!(decode(&blob, d ^ 1, 2).is_none(), "another file");
        assert!(decode(&blob, d, 3).is_none(), "another layout");
        assert!(decode(&blob[..blob.len() - 1], d, 2).is_none(), "truncated");
        assert!(decode(&[], d, 2).is_none(), "empty");
    }

    #[test]
    fn one_changed_byte_changes_the_digest() {
        let text: Vec<u8> = (0..1000u32)
            .flat_map(|i| i.to_string().into_bytes())
            .collect();
        let d = digest(&text);
        for k in [0, 7, 8, 500, text.len() - 1] {
            let mut t = text.clone();
            t[k] ^= 1;
            assert_ne!(digest(&t), d, "byte {k}");
        }
        assert_ne!(digest(&text[..text.len() - 1]), d, "shorter");
    }
}
