//! Fields echoed back in error messages, clipped so that a huge field does not flood the
//! terminal. A leaf module: the errors of every file format use it.

/// The longest prefix of a field echoed in an error message, in characters.
pub const ECHO_CHARS: usize = 60;

/// A field as echoed in an error message: itself when short, else its first
/// [`ECHO_CHARS`] characters, `…` and its length, so that a huge field does not flood the
/// terminal.
///
/// ```
/// use structid_io::echo::clip; // also `structid_io::error::clip`, `structid_io::data_file::clip`
/// assert_eq!(clip("abc"), "abc");
/// let long = "x".repeat(1000);
/// assert_eq!(clip(&long), format!("{}… (1000 characters)", "x".repeat(60)));
/// ```
pub fn clip(field: &str) -> std::borrow::Cow<'_, str> {
    match field.char_indices().nth(ECHO_CHARS) {
        None => std::borrow::Cow::Borrowed(field),
        Some((end, _)) => std::borrow::Cow::Owned(format!(
            "{}… ({} characters)",
            &field[..end],
            field.chars().count()
        )),
    }
}
