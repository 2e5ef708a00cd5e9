//! The tokenizer the text readers share.

use super::{MAX_COORDINATE, MAX_COUNT, MeshError};

/// Whitespace-separated tokens with their line numbers; `#` starts a comment to the end of
/// the line (TetGen, Medit).
pub(super) struct Tokens<'a> {
    file: &'a str,
    toks: Vec<(usize, &'a str)>,
    pos: usize,
    last_line: usize,
}

impl<'a> Tokens<'a> {
    pub(super) fn new(file: &'a str, text: &'a str, comments: bool) -> Self {
        let mut toks = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let line = if comments {
                line.split('#').next().unwrap_or("")
            } else {
                line
            };
            toks.extend(line.split_whitespace().map(|t| (n + 1, t)));
        }
        let last_line = text.lines().count().max(1);
        Self {
            file,
            toks,
            pos: 0,
            last_line,
        }
    }

    pub(super) fn err(&self, line: usize, message: impl Into<String>) -> MeshError {
        MeshError {
            file: self.file.to_string(),
            line,
            message: message.into(),
        }
    }

    pub(super) fn line(&self) -> usize {
        self.toks.get(self.pos).map_or(self.last_line, |t| t.0)
    }

    pub(super) fn next(&mut self, what: &str) -> Result<(usize, &'a str), MeshError> {
        match self.toks.get(self.pos) {
            Some(&t) => {
                self.pos += 1;
                Ok(t)
            }
            None => Err(self.err(
                self.last_line,
                format!("file ends where {what} was expected (truncated?)"),
            )),
        }
    }

    pub(super) fn peek(&self) -> Option<&'a str> {
        self.toks.get(self.pos).map(|t| t.1)
    }

    pub(super) fn int(&mut self, what: &str) -> Result<i64, MeshError> {
        let (line, t) = self.next(what)?;
        t.parse::<i64>()
            .map_err(|_| self.err(line, format!("{what}: `{t}` is not an integer")))
    }

    pub(super) fn count(&mut self, what: &str) -> Result<usize, MeshError> {
        let line = self.line();
        let n = self.int(what)?;
        if n < 0 || n as u64 > MAX_COUNT as u64 {
            return Err(self.err(
                line,
                format!("{what}: {n} is not a count between 0 and {MAX_COUNT}"),
            ));
        }
        Ok(n as usize)
    }

    pub(super) fn real(&mut self, what: &str) -> Result<f64, MeshError> {
        let (line, t) = self.next(what)?;
        let v = t
            .parse::<f64>()
            .map_err(|_| self.err(line, format!("{what}: `{t}` is not a number")))?;
        if !v.is_finite() || v.abs() > MAX_COORDINATE {
            return Err(self.err(
                line,
                format!("{what}: `{t}` is not finite or exceeds {MAX_COORDINATE:e} in magnitude"),
            ));
        }
        Ok(v)
    }

    pub(super) fn point(&mut self, what: &str) -> Result<[f64; 3], MeshError> {
        Ok([self.real(what)?, self.real(what)?, self.real(what)?])
    }

    pub(super) fn expect(&mut self, word: &str) -> Result<(), MeshError> {
        let (line, t) = self.next(word)?;
        if t != word {
            return Err(self.err(line, format!("expected `{word}`, found `{t}`")));
        }
        Ok(())
    }

    /// Skips tokens up to the end of the current line.
    pub(super) fn skip_line(&mut self, line: usize) {
        while self.toks.get(self.pos).is_some_and(|t| t.0 == line) {
            self.pos += 1;
        }
    }
}
