//! An MDF 4 file checked before the `mdf4-rs` crate reads it.
//!
//! The crate (0.3.0) follows the file's links without checking them: a link past the end of
//! the file panics, a data group, channel group or channel chain that comes back to itself
//! grows memory until the process aborts, an `##HL` block that links to itself loops
//! forever, and sizes in block headers become allocations. Everything the crate will do with
//! the file is therefore checked here first, on the bytes that it is then given:
//!
//! 1. The identification block (`MDF     ` or `UnFinMF `, version 4.10 to 4.99) and the
//!    `##HD` block at offset 64.
//! 2. Every block reachable from `##HD` through links (and, for `##HL`, through the address
//!    after its links, which the crate reads as a link when the links are all 0): each link
//!    is 0 or the offset of a block header inside the file (`##` and two upper-case ASCII
//!    letters, a length of at least 24 bytes that fits in the file, a link count that fits
//!    in the length); blocks the crate reads at fixed offsets are long enough for them
//!    (`##HD`, `##DG`, `##CG`, `##CN`, `##CC`, `##DL`); at most one block per 24 bytes of
//!    the file.
//! 3. No cycle among the links (an iterative depth-first search with colours). Links that
//!    the standard lets point back (a channel's attachments and default X axis, a channel
//!    group's master, an event's parent, range and scope, a hierarchy's or array's element
//!    references, a channel's data link to another channel or group) are checked for
//!    bounds only; the crate does not follow them.
//! 4. The walk the crate makes, made first: data groups, their channel groups and channels
//!    (each reached once: a channel group or channel shared by two chains is refused), the
//!    conversions, the data chains (`##DT`, `##DL`, `##HL`; each data block listed once;
//!    `##DZ` and `##DV`, which the crate cannot read here, refused with their names), the
//!    record IDs (1, 2, 4 or 8 bytes; unique among a sorted group's channel groups), a record
//!    size above 0 and, in a finalized file, a cycle count no larger than the records its
//!    data holds. From this walk come the costs the crate and twinbench will incur: the
//!    samples read ([`MAX_CELLS`]), the work per sample (table conversions, formulas:
//!    [`MAX_WORK`]) and the block structures and texts held ([`MAX_METADATA`]).
//!
//! Every refusal names the block by its type and offset, and what is wrong.

use crate::error::MdfError;
use std::collections::{HashMap, HashSet};

/// The longest algebraic conversion formula read (the crate parses it recursively, for every
/// sample).
pub const MAX_FORMULA: u64 = 256;
/// The most samples read from one file, all channels together and the table built from them
/// (2^28: 2 GiB of 64-bit floats, what a 2 GiB file of doubles holds).
pub const MAX_CELLS: u64 = 1 << 28;
/// The most steps of work (samples times the cost of their conversion, data blocks walked
/// per channel, bytes scanned for record IDs).
pub const MAX_WORK: u64 = 1 << 31;
/// The most bytes of block structures (data groups, channel groups, channels, conversions)
/// the crate holds, and of names and units read.
pub const MAX_METADATA: u64 = 256 << 20;

/// Whether twinbench reads a channel's values: a fixed-length value (`cn_type` 0) or a master
/// (2, 3), of a numeric data type (0 to 5), without a conversion to text (7 to 11). The rest
/// (variable-length and synchronisation channels, strings, byte arrays, text tables) is not
/// a number of a table and is skipped. Shared by the check and the reader.
pub fn reads_channel(cn_type: u8, data_type: u8, conversion: Option<u8>) -> bool {
    matches!(cn_type, 0 | 2 | 3) && data_type <= 5 && !matches!(conversion, Some(7..=11))
}

/// A block header.
#[derive(Clone, Copy, Debug)]
struct Block {
    at: u64,
    id: [u8; 4],
    len: u64,
    links: u64,
}

impl Block {
    fn is(&self, id: &[u8; 4]) -> bool {
        &self.id == id
    }
    fn id(&self) -> &str {
        // Checked to be `##` and two upper-case ASCII letters.
        std::str::from_utf8(&self.id).unwrap_or("####")
    }
    fn name(&self) -> String {
        format!("the {} at offset {}", self.id(), self.at)
    }
}

/// The fields of each link of the blocks twinbench reads, for messages.
fn link_name(id: &[u8; 4], i: u64) -> Option<&'static str> {
    let names: &[&str] = match id {
        b"##HD" => &[
            "first data group",
            "file history",
            "channel hierarchy",
            "first attachment",
            "first event",
            "comment",
        ],
        b"##DG" => &["next data group", "first channel group", "data", "comment"],
        b"##CG" => &[
            "next channel group",
            "first channel",
            "acquisition name",
            "acquisition source",
            "first sample reduction",
            "comment",
            "master channel group",
        ],
        b"##CN" => &[
            "next channel",
            "composition",
            "name",
            "source",
            "conversion",
            "data",
            "unit",
            "comment",
        ],
        b"##CC" => &["name", "unit", "comment", "inverse"],
        b"##DL" => &["next data list"],
        b"##HL" => &["first data list"],
        b"##SI" => &["name", "path", "comment"],
        b"##FH" => &["next file history", "comment"],
        b"##AT" => &["next attachment", "file name", "MIME type", "comment"],
        b"##EV" => &["next event", "parent", "range", "name", "comment"],
        _ => &[],
    };
    names.get(i as usize).copied()
}

/// The file being checked.
struct File<'a> {
    bytes: &'a [u8],
    size: u64,
    /// Every block reachable from `##HD`, by offset (after [`File::blocks`]).
    blocks: HashMap<u64, Block>,
}

fn le(bytes: &[u8], at: u64, n: usize) -> u64 {
    let at = usize::try_from(at).unwrap_or(usize::MAX);
    match at.checked_add(n).and_then(|end| bytes.get(at..end)) {
        Some(b) => b
            .iter()
            .rev()
            .fold(0u64, |acc, &x| (acc << 8) | u64::from(x)),
        None => 0,
    }
}

impl<'a> File<'a> {
    fn u64(&self, at: u64) -> u64 {
        le(self.bytes, at, 8)
    }
    fn u32(&self, at: u64) -> u64 {
        le(self.bytes, at, 4)
    }
    fn u16(&self, at: u64) -> u64 {
        le(self.bytes, at, 2)
    }
    fn u8(&self, at: u64) -> u8 {
        le(self.bytes, at, 1) as u8
    }

    /// Link `i` of a block (its link count checked against its length).
    fn link(&self, b: &Block, i: u64) -> u64 {
        self.u64(b.at + 24 + 8 * i)
    }

    /// Where a link is, for messages: "the ##DG at offset 168, link 0 (next data group)".
    fn origin(b: &Block, i: u64) -> String {
        if b.is(b"##HL") && i == b.links {
            return format!(
                "{}, the address after its links (read as its next block when its links are all 0)",
                b.name()
            );
        }
        match link_name(&b.id, i) {
            Some(n) => format!("{}, link {i} ({n})", b.name()),
            None => format!("{}, link {i}", b.name()),
        }
    }

    /// The block header at `at`, reached from `from`.
    fn header(&self, at: u64, from: &str) -> Result<Block, MdfError> {
        let size = self.size;
        if at >= size || size - at < 24 {
            return Err(MdfError::PastEnd {
                from: from.to_string(),
                at,
                size,
            });
        }
        let i = at as usize;
        let id: [u8; 4] = self.bytes[i..i + 4].try_into().expect("4 bytes");
        if !(id[0] == b'#'
            && id[1] == b'#'
            && id[2].is_ascii_uppercase()
            && id[3].is_ascii_uppercase())
        {
            return Err(MdfError::NoBlock {
                from: from.to_string(),
                at,
                found: id.escape_ascii().to_string(),
            });
        }
        let b = Block {
            at,
            id,
            len: self.u64(at + 8),
            links: self.u64(at + 16),
        };
        if b.len < 24 {
            return Err(MdfError::ShortBlock {
                block: b.name(),
                length: b.len,
            });
        }
        if b.len > size - at {
            return Err(MdfError::LongBlock {
                block: b.name(),
                length: b.len,
                size,
            });
        }
        if b.links > (b.len - 24) / 8 {
            return Err(MdfError::LinksOverflow {
                block: b.name(),
                links: b.links,
                length: b.len,
            });
        }
        Ok(b)
    }

    /// Link `i` of a block; for `i` = its link count, the address after the links of an
    /// `##HL` whose links are all 0 (the crate reads it as its next block); `None` after the
    /// last.
    fn edge(&self, b: &Block, i: u64) -> Option<u64> {
        if i < b.links {
            return Some(self.link(b, i));
        }
        let hl_next = i == b.links
            && b.is(b"##HL")
            && 24 + 8 * b.links + 8 <= b.len
            && (0..b.links).all(|k| self.link(b, k) == 0);
        hl_next.then(|| self.u64(b.at + 24 + 8 * b.links))
    }

    /// The links of a block as (number, target), [`File::edge`] by [`File::edge`].
    fn links_of(&self, b: &Block) -> Vec<(u64, u64)> {
        (0..)
            .map_while(|i| self.edge(b, i).map(|t| (i, t)))
            .collect()
    }

    /// The blocks the crate reads at fixed offsets are long enough for them.
    fn fixed_layout(&self, b: &Block) -> Result<(), MdfError> {
        let (links, len) = match &b.id {
            b"##HD" => (6, 104),
            b"##DG" => (4, 64),
            b"##CG" => (6, 104),
            b"##CN" => (8, 160),
            b"##CC" => {
                // Links, then type, precision, flags, reference and value counts (8 bytes),
                // then the values.
                let data = 24 + 8 * b.links;
                let values = self.u16(b.at + data + 6);
                (4, data + 8 + 8 * values)
            }
            b"##DL" => {
                let data = 24 + 8 * b.links;
                let fixed = if self.u8(b.at + data) & 1 != 0 {
                    16
                } else {
                    8 + 8 * self.u32(b.at + data + 4)
                };
                (1, data + fixed)
            }
            _ => return Ok(()),
        };
        if b.links < links || b.len < len {
            return Err(MdfError::Layout {
                block: b.name(),
                links: b.links,
                length: b.len,
                links_needed: links,
                length_needed: len,
            });
        }
        Ok(())
    }

    /// Steps 1 and 2: the identification and header blocks, then every reachable block.
    fn blocks(&mut self) -> Result<(), MdfError> {
        let size = self.size;
        if size < 64 + 104 {
            return Err(MdfError::ShortFile { size });
        }
        let file_id = &self.bytes[0..8];
        if file_id != b"MDF     " && file_id != b"UnFinMF " {
            return Err(MdfError::NotMdf {
                found: file_id.escape_ascii().to_string(),
            });
        }
        let version = std::str::from_utf8(&self.bytes[8..16])
            .ok()
            .map(|s| s.trim_end_matches('\0').trim());
        let number = version.and_then(|v| {
            let mut parts = v.split('.');
            let major: u32 = parts.next()?.parse().ok()?;
            let minor: u32 = parts.next().unwrap_or("0").parse().ok()?;
            (major == 4 && minor < 100).then(|| major * 100 + minor)
        });
        if number.is_none_or(|n| n < 410) {
            return Err(MdfError::Version {
                found: self.bytes[8..16].escape_ascii().to_string(),
            });
        }
        let hd = self.header(64, "the identification block")?;
        if !hd.is(b"##HD") {
            return Err(MdfError::NoHeader { block: hd.name() });
        }
        let max_blocks = size / 24;
        let mut todo = vec![hd];
        self.blocks.insert(hd.at, hd);
        while let Some(b) = todo.pop() {
            self.fixed_layout(&b)?;
            for (i, target) in self.links_of(&b) {
                if target == 0 || self.blocks.contains_key(&target) {
                    continue;
                }
                let t = self.header(target, &Self::origin(&b, i))?;
                if self.blocks.len() as u64 >= max_blocks {
                    return Err(MdfError::TooManyBlocks {
                        limit: max_blocks,
                        size,
                    });
                }
                self.blocks.insert(target, t);
                todo.push(t);
            }
        }
        Ok(())
    }

    /// Whether link `i` of `b`, to `target`, is a reference the standard lets point back
    /// (not followed by the crate; bounds-checked only).
    fn is_reference(&self, b: &Block, i: u64, target: &Block) -> bool {
        match &b.id {
            b"##CN" => {
                i >= 8
                    || (i == 5 && (target.is(b"##CG") || target.is(b"##CN") || target.is(b"##AT")))
            }
            b"##CG" => i >= 6,
            b"##EV" => i == 1 || i == 2 || i >= 5,
            b"##CH" => i >= 4,
            b"##CA" => i >= 1,
            _ => false,
        }
    }

    /// Step 3: no cycle among the links the crate may follow (an iterative depth-first
    /// search with colours: grey on the path, black done).
    fn no_cycle(&self) -> Result<(), MdfError> {
        const GREY: u8 = 1;
        const BLACK: u8 = 2;
        let mut colour: HashMap<u64, u8> = HashMap::with_capacity(self.blocks.len());
        let mut path: Vec<Frame> = Vec::new();
        let hd = self.blocks[&64];
        colour.insert(hd.at, GREY);
        path.push((hd, 0));
        while let Some(frame) = path.last_mut() {
            let (b, i) = *frame;
            let Some(target) = self.edge(&b, i) else {
                colour.insert(b.at, BLACK);
                path.pop();
                continue;
            };
            frame.1 += 1;
            if target == 0 {
                continue;
            }
            let t = self.blocks[&target];
            if self.is_reference(&b, i, &t) {
                continue;
            }
            match colour.get(&target) {
                Some(&GREY) => {
                    let start = path.iter().position(|(p, _)| p.at == target).unwrap_or(0);
                    let mut cycle: Vec<String> = path[start..]
                        .iter()
                        .map(|(p, _)| format!("{} at {}", p.id(), p.at))
                        .collect();
                    if cycle.len() > 8 {
                        let n = cycle.len();
                        cycle.splice(4..n - 3, ["...".to_string()]);
                    }
                    cycle.push(format!("{} at {}", t.id(), t.at));
                    return Err(MdfError::Cycle {
                        from: Self::origin(&b, i),
                        target: if target == b.at {
                            "the same block".to_string()
                        } else {
                            t.name()
                        },
                        cycle,
                    });
                }
                Some(_) => {}
                None => {
                    colour.insert(target, GREY);
                    path.push((t, 0));
                }
            }
        }
        Ok(())
    }

    /// The block at a link, of the type the crate expects there.
    fn expect(&self, at: u64, id: &[u8; 4], from: &str) -> Result<Block, MdfError> {
        let b = self.blocks[&at];
        if !b.is(id) {
            return Err(MdfError::Unexpected {
                from: from.to_string(),
                block: b.name(),
                expected: String::from_utf8_lossy(id).into_owned(),
            });
        }
        Ok(b)
    }

    /// The length of the text or metadata block at `at` (what the crate reads as a string),
    /// 0 for none.
    fn text_len(&self, at: u64) -> u64 {
        match self.blocks.get(&at) {
            Some(b) if b.is(b"##TX") || b.is(b"##MD") => b.len - 24,
            _ => 0,
        }
    }
}

/// A block on the search's path and the number of the next link to look at.
type Frame = (Block, u64);

/// A channel as the crate reads it (fields at the crate's fixed offsets).
struct Channel {
    read: bool,
    master: bool,
    /// Steps per sample: 1, more for table look-ups and formulas.
    cost: u64,
}

/// A channel group as the crate reads it.
struct Group {
    block: Block,
    record_id: u64,
    cycles: u64,
    /// Record ID, data bytes and invalidation bytes.
    record: u64,
    channels: Vec<Channel>,
}

/// The costs of reading the file, summed over the walk.
#[derive(Default)]
struct Costs {
    cells: u64,
    work: u64,
    metadata: u64,
    /// Data channels of groups with a time channel, and their longest record count (the
    /// table twinbench builds).
    table_channels: u64,
    table_rows: u64,
}

/// Step 4: the crate's walk, made first.
struct Walk<'f, 'a> {
    file: &'f File<'a>,
    unfinalized: bool,
    /// Data groups, channel groups and channels met (each may be met once).
    structure: HashSet<u64>,
    /// Data blocks, data lists and `##HL` blocks met in data chains (each once).
    data: HashSet<u64>,
    costs: Costs,
}

impl Walk<'_, '_> {
    fn once(&mut self, b: &Block, what: &'static str) -> Result<(), MdfError> {
        let set = if what == "data" {
            &mut self.data
        } else {
            &mut self.structure
        };
        if !set.insert(b.at) {
            return Err(MdfError::LinkedTwice {
                block: b.name(),
                what,
            });
        }
        Ok(())
    }

    /// The blocks `id` of the list that `parent`'s link `link` starts (each linking the next
    /// by its link 0), each met once (`what`), each as `read` makes it, in the list's order.
    fn linked<T>(
        &mut self,
        parent: &Block,
        link: u64,
        id: &[u8; 4],
        what: &'static str,
        mut read: impl FnMut(&mut Self, &Block) -> Result<T, MdfError>,
    ) -> Result<Vec<T>, MdfError> {
        let f = self.file;
        let mut out = Vec::new();
        let mut from = File::origin(parent, link);
        let mut at = f.link(parent, link);
        while at != 0 {
            let block = f.expect(at, id, &from)?;
            self.once(&block, what)?;
            out.push(read(self, &block)?);
            from = File::origin(&block, 0);
            at = f.link(&block, 0);
        }
        Ok(out)
    }

    fn run(mut self) -> Result<Costs, MdfError> {
        let f = self.file;
        let hd = f.blocks[&64];
        self.linked(&hd, 0, b"##DG", "a data group", |w, dg| w.data_group(dg))?;
        Ok(self.costs)
    }

    fn data_group(&mut self, dg: &Block) -> Result<(), MdfError> {
        let f = self.file;
        self.costs.metadata += 256;
        let rid = u64::from(f.u8(dg.at + 56));
        if !matches!(rid, 0 | 1 | 2 | 4 | 8) {
            return Err(MdfError::RecordIdSize {
                block: dg.name(),
                size: rid,
            });
        }
        let fragments = self.data_chain(dg)?;
        let groups = self.linked(dg, 1, b"##CG", "a channel group", |w, cg| {
            w.channel_group(cg, rid)
        })?;
        let sorted = rid == 0 || groups.len() <= 1;
        let records: Vec<u64> = if sorted {
            groups
                .iter()
                .map(|g| match g.record {
                    0 => 0,
                    r => fragments.iter().map(|&(_, len)| len / r).sum(),
                })
                .collect()
        } else {
            self.scan_records(dg, rid, &groups, &fragments)?
        };
        let data_bytes: u64 = fragments.iter().map(|&(_, len)| len).sum();
        for (g, &n) in groups.iter().zip(&records) {
            let read = g.channels.iter().filter(|c| c.read).count() as u64;
            if read == 0 {
                continue;
            }
            if g.record == 0 {
                return Err(MdfError::EmptyRecords {
                    block: g.block.name(),
                });
            }
            if !self.unfinalized && g.cycles > n {
                return Err(MdfError::CycleCount {
                    block: g.block.name(),
                    cycles: g.cycles,
                    record: g.record,
                    records: n,
                });
            }
            let c = &mut self.costs;
            for ch in g.channels.iter().filter(|c| c.read) {
                c.cells = c.cells.saturating_add(n);
                // Per channel the crate walks the data chain, scans unsorted data for its
                // records and decodes and converts each sample.
                c.work = c
                    .work
                    .saturating_add(fragments.len() as u64)
                    .saturating_add(n.saturating_mul(ch.cost));
                if !sorted {
                    c.work = c
                        .work
                        .saturating_add(data_bytes)
                        .saturating_add(groups.len() as u64);
                }
            }
            if g.channels.iter().any(|c| c.read && c.master) && read > 1 {
                c.table_channels += read - 1;
                c.table_rows = c.table_rows.max(n);
            }
        }
        Ok(())
    }

    fn channel_group(&mut self, cg: &Block, rid: u64) -> Result<Group, MdfError> {
        let f = self.file;
        self.costs.metadata += 256;
        let channels = self.linked(cg, 1, b"##CN", "a channel", |w, cn| w.channel(cn))?;
        Ok(Group {
            block: *cg,
            record_id: f.u64(cg.at + 72),
            cycles: f.u64(cg.at + 80),
            record: rid + f.u32(cg.at + 96) + f.u32(cg.at + 100),
            channels,
        })
    }

    fn channel(&mut self, cn: &Block) -> Result<Channel, MdfError> {
        let f = self.file;
        let cn_type = f.u8(cn.at + 88);
        let data_type = f.u8(cn.at + 90);
        let bit_offset = f.u8(cn.at + 91);
        let bits = f.u32(cn.at + 96);
        let mut metadata = 400;
        let mut conversion = None;
        let mut cost = 1;
        let cc_at = f.link(cn, 4);
        if cc_at != 0 {
            // Every channel's conversion is read when the file is opened (a shared one once
            // per channel), with an algebraic conversion's formula.
            let cc = f.expect(cc_at, b"##CC", &File::origin(cn, 4))?;
            let data = cc.at + 24 + 8 * cc.links;
            let kind = f.u8(data);
            let values = f.u16(data + 6);
            metadata += 256 + 8 * (cc.links - 4 + values);
            conversion = Some(kind);
            match kind {
                4..=6 => cost += values,
                3 if cc.links > 4 => {
                    let formula = f.text_len(f.link(&cc, 4));
                    if formula > MAX_FORMULA {
                        return Err(MdfError::Formula {
                            channel: cn.name(),
                            conversion: cc.name(),
                            length: formula,
                            limit: MAX_FORMULA,
                        });
                    }
                    metadata += formula;
                    cost += formula;
                }
                _ => {}
            }
        }
        let read = reads_channel(cn_type, data_type, conversion);
        if read {
            if data_type <= 3 && !(1..=64).contains(&bits) {
                return Err(MdfError::IntegerBits {
                    channel: cn.name(),
                    bits,
                });
            }
            if bit_offset > 7 {
                return Err(MdfError::BitOffset {
                    channel: cn.name(),
                    offset: bit_offset,
                });
            }
            metadata += f.text_len(f.link(cn, 2)) + f.text_len(f.link(cn, 6));
        }
        self.costs.metadata = self.costs.metadata.saturating_add(metadata);
        Ok(Channel {
            read,
            master: matches!(cn_type, 2 | 3),
            cost,
        })
    }

    /// The next block of an `##HL` as the crate finds it: its first link that is not 0, else
    /// the address after its links.
    fn hl_next(&self, hl: &Block) -> Result<u64, MdfError> {
        match self.file.links_of(hl).iter().find(|&&(_, t)| t != 0) {
            Some(&(_, t)) => Ok(t),
            None => Err(MdfError::NoDataBlock { block: hl.name() }),
        }
    }

    /// The data blocks of a data group in the crate's order: (offset of the data, bytes).
    fn data_chain(&mut self, dg: &Block) -> Result<Vec<(u64, u64)>, MdfError> {
        let f = self.file;
        let mut out = Vec::new();
        let mut from = File::origin(dg, 2);
        let mut at = f.link(dg, 2);
        while at != 0 {
            let b = f.blocks[&at];
            self.once(&b, "data")?;
            match &b.id {
                b"##DT" => {
                    // An unfinalized file's last data block may say 24 bytes and run to the
                    // end of the file; the crate reads it so.
                    let len = if self.unfinalized && b.len == 24 {
                        f.size - b.at - 24
                    } else {
                        b.len - 24
                    };
                    out.push((b.at + 24, len));
                    at = 0;
                }
                b"##DL" => {
                    for i in 1..b.links {
                        let mut frag = f.link(&b, i);
                        if frag == 0 {
                            continue;
                        }
                        let mut frag_from = File::origin(&b, i);
                        loop {
                            let fb = f.blocks[&frag];
                            if !fb.is(b"##HL") {
                                break;
                            }
                            self.once(&fb, "data")?;
                            frag = self.hl_next(&fb)?;
                            frag_from = fb.name();
                        }
                        let fb = f.blocks[&frag];
                        if !fb.is(b"##DT") {
                            return Err(not_data(&fb, &frag_from));
                        }
                        self.once(&fb, "data")?;
                        out.push((fb.at + 24, fb.len - 24));
                    }
                    from = File::origin(&b, 0);
                    at = f.link(&b, 0);
                }
                b"##HL" => {
                    from = b.name();
                    at = self.hl_next(&b)?;
                }
                _ => return Err(not_data(&b, &from)),
            }
        }
        Ok(out)
    }

    /// The records of each channel group of an unsorted data group (record IDs before each
    /// record), counted as the crate reads them.
    fn scan_records(
        &self,
        dg: &Block,
        rid: u64,
        groups: &[Group],
        fragments: &[(u64, u64)],
    ) -> Result<Vec<u64>, MdfError> {
        let mut sizes: HashMap<u64, u64> = HashMap::new();
        for g in groups {
            if sizes.insert(g.record_id, g.record).is_some() {
                return Err(MdfError::SharedRecordId {
                    block: dg.name(),
                    record_id: g.record_id,
                    second: g.block.name(),
                });
            }
        }
        let mut counts: HashMap<u64, u64> = HashMap::new();
        for &(start, len) in fragments {
            let data = &self.file.bytes[start as usize..(start + len) as usize];
            let mut pos = 0u64;
            while pos + rid <= len {
                let id = le(data, pos, rid as usize);
                match sizes.get(&id) {
                    None => pos += 1,
                    Some(&size) => {
                        if pos + size > len {
                            break;
                        }
                        *counts.entry(id).or_default() += 1;
                        pos += size;
                    }
                }
            }
        }
        Ok(groups
            .iter()
            .map(|g| counts.get(&g.record_id).copied().unwrap_or(0))
            .collect())
    }
}

/// Why a block met in a data chain is not one the crate can read (`##DT`, or in a data
/// group's chain `##DL` and `##HL`).
fn not_data(b: &Block, from: &str) -> MdfError {
    let (from, block) = (from.to_string(), b.name());
    match &b.id {
        b"##DZ" => MdfError::Compressed { from, block },
        b"##DV" => MdfError::NoInvalidation { from, block },
        _ => MdfError::NotData { from, block },
    }
}

/// Checks an MDF 4 file's bytes (see the module's documentation); the error says what is
/// wrong and where (the caller adds the file's name).
pub fn check(bytes: &[u8]) -> Result<(), MdfError> {
    let mut file = File {
        bytes,
        size: bytes.len() as u64,
        blocks: HashMap::new(),
    };
    file.blocks()?;
    file.no_cycle()?;
    let costs = Walk {
        file: &file,
        unfinalized: &bytes[0..8] == b"UnFinMF ",
        structure: HashSet::new(),
        data: HashSet::new(),
        costs: Costs::default(),
    }
    .run()?;
    let table = (1 + costs.table_channels).saturating_mul(costs.table_rows);
    let cells = costs.cells.saturating_add(table);
    if cells > MAX_CELLS {
        return Err(MdfError::Cells {
            cells: costs.cells,
            table,
            limit: MAX_CELLS,
        });
    }
    if costs.work > MAX_WORK {
        return Err(MdfError::Work {
            steps: costs.work,
            limit: MAX_WORK,
        });
    }
    if costs.metadata > MAX_METADATA {
        return Err(MdfError::Metadata {
            bytes: costs.metadata,
            limit: MAX_METADATA,
        });
    }
    Ok(())
}
