//! An MDF 4 file is untrusted input (red team 3, N5): a file written by twinbench, then
//! damaged, is refused with a message naming the file, the block and what is wrong, before
//! the `mdf4-rs` crate sees it: no panic, no endless loop, no memory growth. Each case
//! would have crashed, hung or exhausted memory in the crate.

use tb_table::mdf::{read_bytes, to_bytes, MdfError};
use tb_table::{Table, TableError};

/// A file as twinbench writes it: `time` and two channels, `rows` records.
fn valid(rows: usize) -> Vec<u8> {
    let time: Vec<f64> = (0..rows).map(|i| i as f64 * 0.01).collect();
    let v: Vec<f64> = time.iter().map(|t| 20.0 + t).collect();
    let a: Vec<f64> = time.iter().map(|t| -t).collect();
    let t = Table::from_columns(
        "lap",
        vec!["time".into(), "vehicle.v".into(), "vehicle.a".into()],
        vec![time, v, a],
    )
    .unwrap()
    .with_units(vec!["s".into(), "m/s".into(), "m/s2".into()])
    .unwrap();
    to_bytes(&t).unwrap()
}

fn get(b: &[u8], at: u64) -> u64 {
    let at = at as usize;
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

fn put(b: &mut [u8], at: u64, v: u64) {
    let at = at as usize;
    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

fn link(b: &[u8], block: u64, i: u64) -> u64 {
    get(b, block + 24 + 8 * i)
}

fn set_link(b: &mut [u8], block: u64, i: u64, to: u64) {
    put(b, block + 24 + 8 * i, to);
}

/// The offsets of the blocks twinbench writes.
struct Layout {
    dg: u64,
    cg: u64,
    cn: [u64; 3],
    dt: u64,
}

fn layout(b: &[u8]) -> Layout {
    let dg = link(b, 64, 0);
    let cg = link(b, dg, 1);
    let cn0 = link(b, cg, 1);
    let cn1 = link(b, cn0, 0);
    let cn2 = link(b, cn1, 0);
    assert_eq!(&b[dg as usize..dg as usize + 4], b"##DG");
    assert_eq!(&b[cn2 as usize..cn2 as usize + 4], b"##CN");
    Layout {
        dg,
        cg,
        cn: [cn0, cn1, cn2],
        dt: link(b, dg, 2),
    }
}

/// Appends a block (8-byte aligned) and returns its offset.
fn append(b: &mut Vec<u8>, id: &[u8; 4], links: &[u64], data: &[u8]) -> u64 {
    while !b.len().is_multiple_of(8) {
        b.push(0);
    }
    let at = b.len() as u64;
    b.extend_from_slice(id);
    b.extend_from_slice(&[0; 4]);
    let len = 24 + 8 * links.len() + data.len();
    b.extend_from_slice(&(len as u64).to_le_bytes());
    b.extend_from_slice(&(links.len() as u64).to_le_bytes());
    for l in links {
        b.extend_from_slice(&l.to_le_bytes());
    }
    b.extend_from_slice(data);
    at
}

/// The data section of a `##DL` of equal-length blocks.
fn dl_data(count: u32, each: u64) -> Vec<u8> {
    let mut d = vec![1, 0, 0, 0];
    d.extend_from_slice(&count.to_le_bytes());
    d.extend_from_slice(&each.to_le_bytes());
    d
}

/// Reading is refused with a message naming the file, "MDF 4" and every fragment (the
/// block and its offset, where the wording is the point); the refusal, for its kind.
fn refused(bytes: &[u8], fragments: &[&str]) -> MdfError {
    let e = read_bytes(bytes, "damaged.mf4").expect_err("a damaged file must be refused");
    let text = e.to_string();
    assert!(text.starts_with("damaged.mf4: MDF 4: "), "{text}");
    for f in fragments {
        assert!(text.contains(f), "expected {f:?} in: {text}");
    }
    eprintln!("{text}");
    match e {
        TableError::Mdf { file, source } if file == "damaged.mf4" => source,
        other => panic!("not an MDF refusal: {other}"),
    }
}

#[test]
fn the_valid_file_reads_and_so_do_its_bytes() {
    let b = valid(50);
    let t = read_bytes(&b, "lap.mf4").unwrap();
    assert_eq!(t.names(), ["time", "vehicle.v", "vehicle.a"]);
    assert_eq!(t.len(), 50);
    assert_eq!(t.units().unwrap(), ["s", "m/s", "m/s2"]);
}

#[test]
fn a_data_group_linking_to_itself_is_a_cycle() {
    let mut b = valid(50);
    let l = layout(&b);
    set_link(&mut b, l.dg, 0, l.dg);
    refused(
        &b,
        &[&format!(
            "the ##DG at offset {}, link 0 (next data group) leads back to the same block: a cycle",
            l.dg
        )],
    );
}

#[test]
fn a_channel_group_cycle_and_a_channel_cycle_are_refused() {
    let mut b = valid(50);
    let l = layout(&b);
    set_link(&mut b, l.cg, 0, l.cg);
    refused(
        &b,
        &[&format!(
            "the ##CG at offset {}, link 0 (next channel group) leads back to the same block",
            l.cg
        )],
    );

    // The last channel's next is the first one: a cycle of three.
    let mut b = valid(50);
    set_link(&mut b, l.cn[2], 0, l.cn[0]);
    refused(
        &b,
        &[
            &format!(
                "the ##CN at offset {}, link 0 (next channel) leads back to the ##CN at offset {}",
                l.cn[2], l.cn[0]
            ),
            &format!(
                "(##CN at {} -> ##CN at {} -> ##CN at {} -> ##CN at {})",
                l.cn[0], l.cn[1], l.cn[2], l.cn[0]
            ),
        ],
    );
}

#[test]
fn a_data_list_chain_cycle_is_refused() {
    let mut b = valid(50);
    let l = layout(&b);
    let dt_len = get(&b, l.dt + 8) - 24;
    let dl = append(&mut b, b"##DL", &[0, l.dt], &dl_data(1, dt_len));
    set_link(&mut b, dl, 0, dl);
    set_link(&mut b, l.dg, 2, dl);
    refused(
        &b,
        &[&format!("the ##DL at offset {dl}, link 0 (next data list) leads back to the same block: a cycle")],
    );
}

#[test]
fn an_hl_block_linking_to_itself_is_refused() {
    // Through its link.
    let mut b = valid(50);
    let l = layout(&b);
    let hl = append(&mut b, b"##HL", &[0], &[0; 8]);
    set_link(&mut b, hl, 0, hl);
    set_link(&mut b, l.dg, 2, hl);
    refused(
        &b,
        &[&format!("the ##HL at offset {hl}, link 0 (first data list) leads back to the same block: a cycle")],
    );

    // Through the address after its links, which mdf4-rs follows when the links are all 0.
    let mut b = valid(50);
    let hl = append(&mut b, b"##HL", &[0], &[0; 8]);
    put(&mut b, hl + 32, hl);
    set_link(&mut b, l.dg, 2, hl);
    let e = refused(
        &b,
        &[&format!(
            "the ##HL at offset {hl}, the address after its links"
        )],
    );
    assert!(matches!(e, MdfError::Cycle { .. }), "{e}");
}

#[test]
fn a_link_past_the_end_and_a_truncated_file_are_refused() {
    let mut b = valid(50);
    let l = layout(&b);
    let size = b.len() as u64;
    set_link(&mut b, l.dg, 2, size + 4096);
    refused(
        &b,
        &[&format!(
            "the ##DG at offset {}, link 2 (data) points to offset {}, past the end of the file ({size} bytes",
            l.dg,
            size + 4096
        )],
    );

    // A link to the last 8 bytes: no room for a block header.
    let mut b = valid(50);
    set_link(&mut b, l.cn[0], 2, size - 8);
    let e = refused(&b, &["link 2 (name)"]);
    assert!(
        matches!(e, MdfError::PastEnd { at, size: s, .. } if at == size - 8 && s == size),
        "{e}"
    );

    // A link into the middle of a block.
    let mut b = valid(50);
    set_link(&mut b, l.cg, 1, l.cn[0] + 8);
    let e = refused(&b, &["link 1 (first channel)"]);
    assert!(
        matches!(e, MdfError::NoBlock { at, .. } if at == l.cn[0] + 8),
        "{e}"
    );

    // The file cut short: its last block (the data) runs past the end.
    let mut b = valid(50);
    b.truncate(b.len() - 100);
    let e = refused(
        &b,
        &[&format!(
            "the ##DT at offset {} is {} bytes long, past the end of the file ({} bytes; truncated?)",
            l.dt,
            size - l.dt,
            size - 100
        )],
    );
    assert!(matches!(e, MdfError::LongBlock { .. }), "{e}");

    // Cut inside the header block, and nearly empty.
    let e = refused(&valid(50)[..120], &[]);
    assert!(matches!(e, MdfError::ShortFile { size: 120 }), "{e}");
    let e = refused(&valid(50)[..8], &[]);
    assert!(matches!(e, MdfError::ShortFile { size: 8 }), "{e}");
}

#[test]
fn a_huge_cycle_count_is_refused() {
    let mut b = valid(50);
    let l = layout(&b);
    put(&mut b, l.cg + 80, 1 << 62);
    refused(
        &b,
        &[&format!(
            "the ##CG at offset {} says it has 4611686018427387904 records (its cycle count) of 24 bytes, but its data holds 50",
            l.cg
        )],
    );
}

#[test]
fn a_data_block_listed_many_times_is_refused() {
    // One data block listed 100000 times would be read 100000 times for every channel.
    let mut b = valid(50);
    let l = layout(&b);
    let dt_len = get(&b, l.dt + 8) - 24;
    let mut links = vec![0];
    links.extend(std::iter::repeat_n(l.dt, 100_000));
    let dl = append(&mut b, b"##DL", &links, &dl_data(100_000, dt_len));
    set_link(&mut b, l.dg, 2, dl);
    refused(
        &b,
        &[&format!(
            "the ##DT at offset {} is linked twice as data",
            l.dt
        )],
    );
}

#[test]
fn a_channel_in_two_channel_groups_is_refused() {
    // A second channel group with the first one's channels: each channel would be read
    // once per group that lists it.
    let mut b = valid(50);
    let l = layout(&b);
    let cg_len = get(&b, l.cg + 8) as usize;
    let copy = b[l.cg as usize..l.cg as usize + cg_len].to_vec();
    let cg2 = append(&mut b, b"##CG", &[], &[]);
    b.truncate(cg2 as usize);
    b.extend_from_slice(&copy);
    set_link(&mut b, l.cg, 0, cg2);
    refused(
        &b,
        &[&format!(
            "the ##CN at offset {} is linked twice as a channel",
            l.cn[0]
        )],
    );
}

#[test]
fn records_of_zero_bytes_and_impossible_fields_are_refused() {
    let mut b = valid(50);
    let l = layout(&b);
    b[l.cg as usize + 96..l.cg as usize + 104].fill(0);
    let e = refused(&b, &[]);
    assert!(matches!(e, MdfError::EmptyRecords { .. }), "{e}");

    // An integer channel of 0 bits.
    let mut b = valid(50);
    b[l.cn[1] as usize + 90] = 0; // unsigned integer
    b[l.cn[1] as usize + 96..l.cn[1] as usize + 100].copy_from_slice(&0u32.to_le_bytes());
    refused(
        &b,
        &[&format!(
            "the ##CN at offset {} is an integer of 0 bits",
            l.cn[1]
        )],
    );

    // Record IDs of 3 bytes.
    let mut b = valid(50);
    b[l.dg as usize + 56] = 3;
    let e = refused(&b, &[]);
    assert!(matches!(e, MdfError::RecordIdSize { size: 3, .. }), "{e}");

    // A version whose number overflows the crate's arithmetic.
    let mut b = valid(50);
    b[8..16].copy_from_slice(b"999.99  ");
    refused(
        &b,
        &["version \"999.99  \": twinbench reads MDF 4.10 and later"],
    );
    // One that overflowed the check's own arithmetic (found by the mdf4 fuzz target).
    b[8..16].copy_from_slice(b"42949673");
    let e = refused(&b, &[]);
    assert!(
        matches!(&e, MdfError::Version { found } if found == "42949673"),
        "{e}"
    );

    // A block whose length is shorter than its links.
    let mut b = valid(50);
    put(&mut b, l.cn[0] + 16, 1 << 40);
    refused(
        &b,
        &[&format!(
            "the ##CN at offset {} has 1099511627776 links, more than its 160 bytes hold",
            l.cn[0]
        )],
    );

    // A channel block too short for the fields the crate reads at fixed offsets.
    let mut b = valid(50);
    put(&mut b, l.cn[0] + 16, 2);
    let e = refused(&b, &[]);
    assert!(
        matches!(
            e,
            MdfError::Layout {
                links: 2,
                length: 160,
                links_needed: 8,
                length_needed: 160,
                ..
            }
        ),
        "{e}"
    );

    // Compressed data, which the crate cannot read from a data group.
    let mut b = valid(50);
    b[l.dt as usize + 2..l.dt as usize + 4].copy_from_slice(b"DZ");
    let e = refused(&b, &[]);
    assert!(matches!(e, MdfError::Compressed { .. }), "{e}");
}

#[test]
fn a_deeply_nested_formula_is_refused() {
    // The crate parses a formula recursively for every sample: 100000 parentheses would
    // overflow the stack.
    let mut b = valid(50);
    let l = layout(&b);
    let formula = format!("{}X{}", "(".repeat(100_000), ")".repeat(100_000));
    let mut text = formula.into_bytes();
    text.push(0);
    let tx = append(&mut b, b"##TX", &[], &text);
    // Algebraic (3), no values.
    let cc = append(
        &mut b,
        b"##CC",
        &[0, 0, 0, 0, tx],
        &[3, 0, 0, 0, 1, 0, 0, 0],
    );
    set_link(&mut b, l.cn[1], 4, cc);
    refused(
        &b,
        &[&format!(
            "the ##CN at offset {}: the formula of its algebraic conversion (the ##CC at offset {cc}) is 200002 bytes long, more than 256",
            l.cn[1]
        )],
    );
}

#[test]
fn samples_multiplied_by_channels_or_by_a_table_conversion_are_bounded() {
    // One 1 MiB data block of 1-byte records, read by 300 channels: 300 Mi samples.
    let mut b = valid(2);
    let l = layout(&b);
    let dt = append(&mut b, b"##DT", &[], &vec![0u8; 1 << 20]);
    set_link(&mut b, l.dg, 2, dt);
    b[l.cg as usize + 96..l.cg as usize + 100].copy_from_slice(&1u32.to_le_bytes());
    put(&mut b, l.cg + 80, 0);
    let cn = b[l.cn[2] as usize..l.cn[2] as usize + 160].to_vec();
    let mut last = l.cn[2];
    for _ in 0..300 {
        let at = append(&mut b, b"##CN", &[], &[]);
        b.truncate(at as usize);
        b.extend_from_slice(&cn);
        set_link(&mut b, last, 0, at);
        last = at;
    }
    set_link(&mut b, last, 0, 0);
    let e = refused(&b, &[]);
    assert!(
        matches!(
            e,
            MdfError::Cells {
                limit: 268435456,
                ..
            }
        ),
        "{e}"
    );

    // A value table of 65535 entries applied to each of 20000 samples of three channels.
    let mut b = valid(20_000);
    let l = layout(&b);
    let mut data = vec![4, 0, 0, 0, 0, 0, 0xff, 0xff];
    data.extend(std::iter::repeat_n(0u8, 8 * 65535));
    let cc = append(&mut b, b"##CC", &[0, 0, 0, 0], &data);
    for cn in l.cn {
        set_link(&mut b, cn, 4, cc);
    }
    let e = refused(&b, &[]);
    assert!(
        matches!(
            e,
            MdfError::Work {
                limit: 2147483648,
                ..
            }
        ),
        "{e}"
    );
}
