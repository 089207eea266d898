//! LZF decompression (Marc Lehmann's liblzf format), as used by PCD's
//! `binary_compressed` bodies.

/// Decompress LZF `input` into exactly `expected_len` bytes.
///
/// The format is a sequence of runs: a control byte `c < 32` is followed by
/// `c + 1` literal bytes; otherwise `c >> 5` (7 meaning "add the next byte")
/// plus 2 bytes are copied from `((c & 31) << 8) + next + 1` bytes back in the
/// output (overlapping copies allowed).
///
/// # Errors
/// A one-line description when the input is truncated, refers before the
/// start of the output, or does not decompress to exactly `expected_len`.
pub fn lzf_decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, String> {
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
                .ok_or_else(|| format!("LZF literal run at byte {} runs past the end", ip - 1))?;
            if out.len() + len > expected_len {
                return Err(format!(
                    "LZF data decompresses to more than {expected_len} bytes"
                ));
            }
            out.extend_from_slice(lit);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(
                    *input
                        .get(ip)
                        .ok_or_else(|| "LZF back-reference cut short".to_string())?,
                );
                ip += 1;
            }
            let low = usize::from(
                *input
                    .get(ip)
                    .ok_or_else(|| "LZF back-reference cut short".to_string())?,
            );
            ip += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            len += 2;
            if back > out.len() {
                return Err(format!(
                    "LZF back-reference {back} bytes back at output byte {} points before the start",
                    out.len()
                ));
            }
            if out.len() + len > expected_len {
                return Err(format!(
                    "LZF data decompresses to more than {expected_len} bytes"
                ));
            }
            let start = out.len() - back;
            for k in 0..len {
                let b = out[start + k];
                out.push(b);
            }
        }
    }
    if out.len() != expected_len {
        return Err(format!(
            "LZF data decompresses to {} bytes, the header says {expected_len}",
            out.len()
        ));
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

    #[test]
    fn bad_inputs_are_errors() {
        assert!(lzf_decompress(&[5, b'a'], 6).is_err());
        assert!(lzf_decompress(&[(1 << 5), 9], 3).is_err());
        assert!(lzf_decompress(&[0, b'a'], 2).is_err());
    }
}
