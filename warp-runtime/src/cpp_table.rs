//! Tables that the CPU steps share with the CUDA library, read from its C++ headers at compile
//! time, so that each table is written once (in the header, which NVRTC and the host tests'
//! g++ read as it is) and the Rust side cannot drift from it.
//!
//! [`array`] and [`integer`] are `const fn`s: used in a constant, a table or a constant that
//! is missing from the header, or a table of another count than the Rust type says, fails the
//! build.

/// The `N` integers of the initializer of the C array `name` in `header`
/// (`... name[257] = { 0, 0, 3, ... };`), in order, nested braces flattened (`[12][4]`), `//`
/// and `/* */` comments skipped. The integers are decimal and non-negative, optionally with a
/// `u` suffix.
///
/// # Panics
/// Where `name` is not followed by `= {`, a value is not such an integer, or the count is not
/// `N`: at compile time where it is evaluated as a constant (how it is used).
pub(crate) const fn array<const N: usize>(header: &str, name: &str) -> [u32; N] {
    let text = header.as_bytes();
    let mut i = find_declaration(text, name.as_bytes(), b'[');
    // `name[..]...` then `= {`.
    while i < text.len() && text[i] != b'=' {
        i += 1;
    }
    i = skip_space(text, i + 1);
    assert!(
        i < text.len() && text[i] == b'{',
        "the array has no `= {{` initializer"
    );
    let mut out = [0u32; N];
    let mut n = 0;
    let mut depth = 0;
    loop {
        i = skip_space(text, i);
        assert!(i < text.len(), "the initializer is not closed");
        match text[i] {
            b'{' => {
                depth += 1;
                i += 1;
            }
            b'}' => {
                depth -= 1;
                i += 1;
                if depth == 0 {
                    break;
                }
            }
            b',' => i += 1,
            b'0'..=b'9' => {
                let mut v: u32 = 0;
                while i < text.len() && text[i].is_ascii_digit() {
                    v = v * 10 + (text[i] - b'0') as u32;
                    i += 1;
                }
                if i < text.len() && (text[i] == b'u' || text[i] == b'U') {
                    i += 1;
                }
                assert!(n < N, "the initializer has more values than the Rust table");
                out[n] = v;
                n += 1;
            }
            _ => panic!("the initializer holds something other than integers"),
        }
    }
    assert!(
        n == N,
        "the initializer has fewer values than the Rust table"
    );
    out
}

/// The value of the C++ integer constant `name` in `header` (`constexpr i32 name = 8;`, an
/// enumerator `name = 8,`): decimal, non-negative, optionally with a `u` suffix.
///
/// # Panics
/// Where `name` is not followed by `=` and such an integer: at compile time where it is
/// evaluated as a constant (how it is used).
pub(crate) const fn integer(header: &str, name: &str) -> u32 {
    let text = header.as_bytes();
    let mut i = find_declaration(text, name.as_bytes(), b'=');
    i = skip_space(text, i + 1);
    assert!(
        i < text.len() && text[i].is_ascii_digit(),
        "the constant's value is not an integer"
    );
    let mut v: u32 = 0;
    while i < text.len() && text[i].is_ascii_digit() {
        v = v * 10 + (text[i] - b'0') as u32;
        i += 1;
    }
    v
}

/// `to_u16`, `to_u8`: `a`, each value narrowed to the Rust table's type. A `const fn` cannot
/// call `TryFrom`, so one macro writes the check once for each type.
///
/// # Panics
/// Where a value does not fit (at compile time, in a constant).
macro_rules! narrowing {
    ($($name:ident -> $t:ty),*) => {$(
        pub(crate) const fn $name<const N: usize>(a: [u32; N]) -> [$t; N] {
            let mut out = [0 as $t; N];
            let mut k = 0;
            while k < N {
                assert!(a[k] <= <$t>::MAX as u32, "a value does not fit the Rust table's type");
                out[k] = a[k] as $t;
                k += 1;
            }
            out
        }
    )*};
}

narrowing!(to_u16 -> u16, to_u8 -> u8);

/// The index of `next` after the declaration of `name`: the name as a whole word, outside
/// comments, followed by `next` (`[` for an array, `=` for a constant; spaces between).
const fn find_declaration(text: &[u8], name: &[u8], next: u8) -> usize {
    let mut i = 0;
    while i < text.len() {
        let j = skip_space(text, i);
        if j != i {
            i = j;
            continue;
        }
        if starts_with_at(text, i, name) && (i == 0 || !is_ident(text[i - 1])) {
            let after = skip_space(text, i + name.len());
            if after < text.len() && text[after] == next {
                return after;
            }
        }
        i += 1;
    }
    panic!("the header declares nothing of this name")
}

/// The first index at or after `i` that is neither white space nor in a comment.
const fn skip_space(text: &[u8], mut i: usize) -> usize {
    while i < text.len() {
        if text[i].is_ascii_whitespace() {
            i += 1;
        } else if starts_with_at(text, i, b"//") {
            while i < text.len() && text[i] != b'\n' {
                i += 1;
            }
        } else if starts_with_at(text, i, b"/*") {
            i += 2;
            while i < text.len() && !starts_with_at(text, i, b"*/") {
                i += 1;
            }
            i += 2;
        } else {
            break;
        }
    }
    i
}

/// Whether `text[i..]` starts with `p`.
const fn starts_with_at(text: &[u8], i: usize, p: &[u8]) -> bool {
    if i + p.len() > text.len() {
        return false;
    }
    let mut k = 0;
    while k < p.len() {
        if text[i + k] != p[k] {
            return false;
        }
        k += 1;
    }
    true
}

const fn is_ident(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "// t[3] = {9, 9, 9}; in a comment\n\
        static const u8 not_t[2] = {7, 7};\n\
        constexpr i32 K = 8; enum { E = 12u, };\n\
        static const u16 t[2][3] = { // rows\n  {1, 2u, 3}, /* a comment */\n  {40, 5, 600},\n};\n";

    #[test]
    fn reads_the_initializer_in_order() {
        const T: [u32; 6] = array(HEADER, "t");
        assert_eq!(T, [1, 2, 3, 40, 5, 600]);
        assert_eq!(array::<2>(HEADER, "not_t"), [7, 7]);
        assert_eq!(to_u16(T), [1, 2, 3, 40, 5, 600]);
        assert_eq!(to_u8([1, 255]), [1, 255]);
        const K: u32 = integer(HEADER, "K");
        assert_eq!((K, integer(HEADER, "E")), (8, 12));
    }

    #[test]
    #[should_panic(expected = "nothing of this name")]
    fn an_array_is_no_integer() {
        integer(HEADER, "not_t");
    }

    #[test]
    #[should_panic(expected = "fewer values")]
    fn a_short_table_fails() {
        array::<7>(HEADER, "t");
    }

    #[test]
    #[should_panic(expected = "more values")]
    fn a_long_table_fails() {
        array::<5>(HEADER, "t");
    }

    #[test]
    #[should_panic(expected = "nothing of this name")]
    fn a_missing_table_fails() {
        array::<1>(HEADER, "u");
    }

    #[test]
    #[should_panic(expected = "does not fit")]
    fn a_value_too_large_fails() {
        to_u8(array::<6>(HEADER, "t"));
    }
}
