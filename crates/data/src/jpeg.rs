//! Whether a JPEG file is whole: its segments walked from the start-of-image marker to the
//! end-of-image marker. The decoder fills the rows a truncated file lacks with grey and says
//! nothing, so a picture cut short would be trained on as if the scene were grey there (a
//! truncated PNG, whose chunks carry lengths and checksums, is refused by its decoder).
//!
//! The walk follows the format's own structure, so an end-of-image marker inside an embedded
//! thumbnail (within an APP1 segment, skipped by its length) does not pass for the file's:
//! marker segments carry their length; entropy-coded data after each start-of-scan runs to
//! the next marker that is neither a stuffed `FF 00` nor a restart marker.

/// Start of image.
const SOI: u8 = 0xD8;
/// End of image.
const EOI: u8 = 0xD9;
/// Start of scan.
const SOS: u8 = 0xDA;

/// Whether `bytes` begins as a JPEG does (`FF D8 FF`).
pub(crate) fn is_jpeg(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0xFF, SOI, 0xFF])
}

/// Whether the JPEG `bytes` reaches its end-of-image marker through whole segments (bytes
/// after it, which some cameras append, are allowed).
pub(crate) fn is_complete(bytes: &[u8]) -> bool {
    let mut i = 2;
    loop {
        // Bytes between segments that are not a marker are skipped, as decoders do.
        while i < bytes.len() && bytes[i] != 0xFF {
            i += 1;
        }
        // Any number of fill bytes 0xFF may precede a marker.
        while i < bytes.len() && bytes[i] == 0xFF {
            i += 1;
        }
        let Some(&marker) = bytes.get(i) else {
            return false;
        };
        i += 1;
        match marker {
            EOI => return true,
            // Restart markers and TEM stand alone.
            0xD0..=0xD7 | 0x01 => {}
            _ => {
                let Some(length) = bytes
                    .get(i..i + 2)
                    .map(|b| usize::from(u16::from_be_bytes([b[0], b[1]])))
                else {
                    return false;
                };
                if length < 2 || i + length > bytes.len() {
                    return false;
                }
                i += length;
                if marker == SOS {
                    match end_of_scan(bytes, i) {
                        Some(end) => i = end,
                        None => return false,
                    }
                }
            }
        }
    }
}

/// The position of the marker that ends the entropy-coded data starting at `from`, if the
/// data ends before the file does.
fn end_of_scan(bytes: &[u8], from: usize) -> Option<usize> {
    let mut i = from;
    while i + 1 < bytes.len() {
        if bytes[i] == 0xFF {
            let next = bytes[i + 1];
            if next != 0x00 && next != 0xFF && !(0xD0..=0xD7).contains(&next) {
                return Some(i);
            }
        }
        i += 1;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built JPEG skeleton: SOI, an APP0 of 4 payload bytes, an SOS of 2 payload
    /// bytes, entropy data with a stuffed byte and a restart marker, EOI.
    fn skeleton() -> Vec<u8> {
        vec![
            0xFF, SOI, //
            0xFF, 0xE0, 0x00, 0x06, 1, 2, 3, 4, // APP0, length 6
            0xFF, SOS, 0x00, 0x04, 9, 9, // SOS header, length 4
            0x12, 0xFF, 0x00, 0x34, 0xFF, 0xD0, 0x56, // data, a stuffed FF, RST0
            0xFF, EOI,
        ]
    }

    #[test]
    fn a_whole_file_passes_and_every_cut_of_it_fails() {
        let whole = skeleton();
        assert!(is_jpeg(&whole) && is_complete(&whole));
        for cut in 2..whole.len() {
            assert!(!is_complete(&whole[..cut]), "cut at {cut}");
        }
        let mut trailing = whole.clone();
        trailing.extend_from_slice(&[0, 0, 0]);
        assert!(is_complete(&trailing));
    }

    #[test]
    fn an_end_marker_inside_a_segment_is_not_the_files() {
        // An APP1 whose payload holds FF D9 (a thumbnail's end), then the file cut short.
        let cut = [0xFF, SOI, 0xFF, 0xE1, 0x00, 0x06, 0xFF, EOI, 0, 0, 0xFF, SOS, 0x00];
        assert!(!is_complete(&cut));
    }
}
