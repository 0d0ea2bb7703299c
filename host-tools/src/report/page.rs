//! The HTML page of a report: a summary and sections of plots with titles
//! and captions, written atomically with its plots (nothing half-written is
//! ever left in a report directory).

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

use crate::io::atomic::write_bytes_atomic;

/// One axis in index.html: heading and its plots (file, title, caption).
pub type Section = (String, Vec<(String, String, String)>);

/// One report file: its name in the report directory and its content.
pub struct Page {
    pub name: String,
    pub content: String,
}

/// Create `dir` if needed and write `pages` atomically; on error remove what
/// this call created (files that did not exist before, and `dir` if it was
/// created here and is empty again).
pub fn write_pages(dir: &Path, pages: &[Page]) -> Result<Vec<PathBuf>> {
    let dir_existed = dir.is_dir();
    if !dir_existed {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create the report directory", dir.display()))?;
    }
    let mut written: Vec<PathBuf> = Vec::new();
    let mut created: Vec<PathBuf> = Vec::new();
    for p in pages {
        let path = dir.join(&p.name);
        let existed = path.exists();
        if let Err(e) = write_bytes_atomic(&path, p.content.as_bytes()) {
            for c in &created {
                let _ = std::fs::remove_file(c);
            }
            if !dir_existed {
                let _ = std::fs::remove_dir(dir);
            }
            return Err(e);
        }
        if !existed {
            created.push(path.clone());
        }
        written.push(path);
    }
    Ok(written)
}

pub fn html_escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// The report page: `title`, `summary` as preformatted text, then each
/// section's plots with their titles and captions.
pub fn index_html(title: &str, summary: &str, sections: &[Section]) -> String {
    let mut h = String::new();
    h.push_str(
        &"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title}</title>\n\
         <style>\n\
         body { font-family: sans-serif; margin: 2em auto; max-width: 1150px; padding: 0 1em; color: #222; }\n\
         pre { background: #f4f4f4; border: 1px solid #ddd; padding: 1em; white-space: pre-wrap; overflow-wrap: anywhere; }\n\
         img { width: 100%; max-width: 1100px; border: 1px solid #ddd; }\n\
         nav a { margin-right: 1em; }\n\
         p.caption { color: #444; }\n\
         </style>\n</head>\n<body>\n<h1>{title}</h1>\n"
            .replace("{title}", &html_escape(title)),
    );
    if !sections.is_empty() {
        h.push_str("<nav>");
        for (sec_title, entries) in sections {
            if let Some((file, _, _)) = entries.first() {
                let anchor = file.split('_').next().unwrap_or("");
                h.push_str(&format!("<a href=\"#axis-{}\">{}</a>", html_escape(anchor), html_escape(sec_title)));
            }
        }
        h.push_str("</nav>\n");
    }
    h.push_str("<h2>Summary</h2>\n<pre>");
    h.push_str(&html_escape(summary));
    h.push_str("</pre>\n");
    for (title, entries) in sections {
        let anchor = entries.first().map(|e| e.0.split('_').next().unwrap_or("")).unwrap_or("");
        h.push_str(&format!("<h2 id=\"axis-{}\">{}</h2>\n", html_escape(anchor), html_escape(title)));
        for (file, plot_title, caption) in entries {
            h.push_str(&format!(
                "<h3>{}</h3>\n<p class=\"caption\">{}</p>\n<p><a href=\"{f}\"><img src=\"{f}\" alt=\"{}\"></a></p>\n",
                html_escape(plot_title),
                html_escape(caption),
                html_escape(plot_title),
                f = html_escape(file),
            ));
        }
    }
    h.push_str("</body>\n</html>\n");
    h
}

/// `s` with its first character upper-cased: a phrase that also serves
/// inside a sentence (after a colon) made to start one, e.g. in a caption.
pub fn sentence_case(s: &str) -> String {
    let mut chars = s.chars();
    match chars.next() {
        Some(c) => c.to_uppercase().chain(chars).collect(),
        None => String::new(),
    }
}

/// Words ending in a full stop that do not end a sentence.
const ABBREVIATIONS: [&str; 5] = ["e.g.", "i.e.", "cf.", "vs.", "etc."];

/// The sentences of `text` (a caption) that start with a lowercase letter,
/// each as its first few words. A sentence starts at the beginning of the
/// text and after `.`, `!` or `?` followed by white space, except after
/// [`ABBREVIATIONS`]. Report tests (and `scripts/render_check.sh` on the
/// pages) require none.
pub fn lowercase_sentence_starts(text: &str) -> Vec<String> {
    let mut starts = vec![0];
    let mut prev_word_start = 0;
    let mut prev: Option<char> = None;
    for (i, c) in text.char_indices() {
        if c.is_whitespace() {
            let word = text[prev_word_start..i].trim_start_matches(['(', '[', '"']);
            let ends = matches!(prev, Some('.' | '!' | '?')) && !ABBREVIATIONS.contains(&word);
            if ends {
                starts.push(i);
            }
            prev_word_start = i + c.len_utf8();
        }
        prev = Some(c);
    }
    starts
        .into_iter()
        .filter_map(|s| {
            let rest = text[s..].trim_start();
            let first = rest.chars().next()?;
            first.is_lowercase().then(|| rest.split_whitespace().take(4).collect::<Vec<_>>().join(" "))
        })
        .collect()
}

/// The caption sentences of a report page made by [`index_html`] that start
/// in lowercase ([`lowercase_sentence_starts`] of each caption paragraph).
pub fn lowercase_caption_sentences(html: &str) -> Vec<String> {
    const OPEN: &str = "<p class=\"caption\">";
    html.split(OPEN)
        .skip(1)
        .filter_map(|rest| rest.split_once("</p>").map(|(caption, _)| caption))
        .flat_map(|caption| lowercase_sentence_starts(&html_unescape(caption)))
        .collect()
}

/// The inverse of [`html_escape`].
fn html_unescape(s: &str) -> String {
    s.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", "\"").replace("&#39;", "'").replace("&amp;", "&")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_sentences_starting_in_lowercase() {
        assert!(lowercase_sentence_starts("Shaded: the band. Dashed: twice it, e.g. 0.5 %.").is_empty());
        assert!(lowercase_sentence_starts("Up to 4000 Hz (i.e. the band). The end… and on.").is_empty());
        assert_eq!(lowercase_sentence_starts("Dashed: twice it. re-measure the FRF when"), ["re-measure the FRF when"]);
        assert_eq!(lowercase_sentence_starts("the first. Then? no!  x"), ["the first. Then? no!", "no! x", "x"]);
    }

    #[test]
    fn finds_lowercase_sentences_in_a_page_captions_only() {
        let sec = |caption: &str| ("Axis x".to_string(), vec![("x_a.svg".into(), "t".into(), caption.to_string())]);
        let good = index_html("r", "summary. lowercase in the summary is fine", &[sec("Fine &amp; <ok>. Also fine.")]);
        assert!(lowercase_caption_sentences(&good).is_empty());
        let bad = index_html("r", "s", &[sec("It's fine. it's not.")]);
        assert_eq!(lowercase_caption_sentences(&bad), ["it's not."]);
    }

    #[test]
    fn sentence_case_upper_cases_the_first_letter() {
        assert_eq!(sentence_case("re-measure the FRF"), "Re-measure the FRF");
        assert_eq!(sentence_case("Already"), "Already");
        assert_eq!(sentence_case(""), "");
    }
}
