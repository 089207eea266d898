//! LZF decompression (Marc Lehmann's liblzf format), as used by PCD's
//! `binary_compressed` bodies.

/// Why LZF data did not decompress. Displays as one line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LzfError {
    /// A literal run, whose control byte is at `at`, runs past the input's
    /// end.
    LiteralPastEnd {
        /// Input byte of the run's control byte.
        at: usize,
    },
    /// A back-reference's length or offset bytes are missing.
    BackReferenceCut,
    /// A back-reference points `back` bytes back from output byte `at`,
    /// before the start.
    BeforeStart {
        /// Bytes back.
        back: usize,
        /// Output byte it is met at.
        at: usize,
    },
    /// The output would grow past the expected length.
    TooLong {
        /// The expected length.
        expected: usize,
    },
    /// The output ends short of the expected length.
    WrongLength {
        /// Bytes decompressed.
        got: usize,
        /// The expected length.
        expected: usize,
    },
}

impl std::fmt::Display for LzfError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LzfError::LiteralPastEnd { at } => {
                write!(f, "LZF literal run at byte {at} runs past the end")
            }
            LzfError::BackReferenceCut => f.write_str("LZF back-reference cut short"),
            LzfError::BeforeStart { back, at } => write!(
                f,
                "LZF back-reference {back} bytes back at output byte {at} points before the start"
            ),
            LzfError::TooLong { expected } => {
                write!(f, "LZF data decompresses to more than {expected} bytes")
            }
            LzfError::WrongLength { got, expected } => write!(
                f,
                "LZF data decompresses to {got} bytes, the header says {expected}"
            ),
        }
    }
}

impl std::error::Error for LzfError {}

/// Decompress LZF `input` into exactly `expected_len` bytes.
///
/// The format is a sequence of runs: a control byte `c < 32` is followed by
/// `c + 1` literal bytes; otherwise `c >> 5` (7 meaning "add the next byte")
/// plus 2 bytes are copied from `((c & 31) << 8) + next + 1` bytes back in the
/// output (overlapping copies allowed).
///
/// # Errors
/// [`LzfError`] when the input is truncated, refers before the start of the
/// output, or does not decompress to exactly `expected_len`.
pub fn lzf_decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, LzfError> {
    // Each input byte yields at most 264/3 output bytes, so a bogus expected
    // length is never reserved.
    let cap = expected_len.min(input.len().saturating_mul(90));
    let mut out: Vec<u8> = Vec::with_capacity(cap);
    let mut ip = 0usize;
    while ip < input.len() {
        let ctrl = usize::from(input[ip]);
        ip += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            let lit = input
                .get(ip..ip + len)
                .ok_or(LzfError::LiteralPastEnd { at: ip - 1 })?;
            if out.len() + len > expected_len {
                return Err(LzfError::TooLong {
                    expected: expected_len,
                });
            }
            out.extend_from_slice(lit);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(*input.get(ip).ok_or(LzfError::BackReferenceCut)?);
                ip += 1;
            }
            let low = usize::from(*input.get(ip).ok_or(LzfError::BackReferenceCut)?);
            ip += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            len += 2;
            if back > out.len() {
                return Err(LzfError::BeforeStart {
                    back,
                    at: out.len(),
                });
            }
            if out.len() + len > expected_len {
                return Err(LzfError::TooLong {
                    expected: expected_len,
                });
            }
            let start = out.len() - back;
            if back >= len {
                // No overlap: one copy.
                out.extend_from_within(start..start + len);
            } else {
                // The copy reads what it writes: byte by byte.
                for k in 0..len {
                    let b = out[start + k];
                    out.push(b);
                }
            }
        }
    }
    if out.len() != expected_len {
        return Err(LzfError::WrongLength {
            got: out.len(),
            expected: expected_len,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::lzf_decompress;

    #[test]
    fn literal_and_overlapping_back_reference() {
        // "abc" literal, then copy 6 bytes from 3 back: "abcabcabc".
        let input = [2, b'a', b'b', b'c', (4 << 5), 2];
        assert_eq!(lzf_decompress(&input, 9).unwrap(), b"abcabcabc");
    }

    /// A back-reference that reads only what was there before it (one
    /// copy), next to one that overlaps what it writes.
    #[test]
    fn back_references_within_and_across_what_they_write() {
        // "abcdef", then 3 bytes from 5 back ("bcd"), then 4 from 2 back
        // ("cdcd", reading its own output).
        let input = [5, b'a', b'b', b'c', b'd', b'e', b'f', (1 << 5), 4, (2 << 5), 1];
        assert_eq!(lzf_decompress(&input, 13).unwrap(), b"abcdefbcdcdcd");
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(lzf_decompress(&[5, b'a'], 6).is_err());
        assert!(lzf_decompress(&[(1 << 5), 9], 3).is_err());
        assert!(lzf_decompress(&[0, b'a'], 2).is_err());
    }
}
