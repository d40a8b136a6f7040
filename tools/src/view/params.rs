//! Request parameters of the viewer's API, parsed and range-checked before
//! any work: every value a request may carry is named here, with its valid
//! range in the message of the error it gets.

use ltm_relight::{Rotation, Weighting};
use std::collections::HashMap;

/// Largest magnitude of an angle, in degrees (angles are taken modulo 360;
/// larger values are refused as nonsense rather than silently reduced).
pub const MAX_ANGLE: f64 = 36_000.0;
/// Longest accepted request target (path and query), in bytes.
pub const MAX_URL: usize = 2048;
/// Longest client identifier.
pub const MAX_CLIENT_ID: usize = 32;

/// A parameter error: HTTP 400 with this message.
#[derive(Debug, Clone, PartialEq)]
pub struct BadRequest(pub String);

impl std::fmt::Display for BadRequest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// What the viewer holds, for range checks.
#[derive(Clone, Copy, Debug)]
pub struct Bounds {
    /// Files opened.
    pub files: usize,
    /// Environment maps listed.
    pub maps: usize,
    /// Area-light textures offered (`uniform` and each `--area-light`).
    pub textures: usize,
    /// Glossy materials offered (each `--brdf`).
    pub materials: usize,
}

/// Largest magnitude of an eye coordinate.
pub const MAX_EYE: f64 = 1e6;

/// A glossy material shaded from an eye (`brdf`, `eye`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlossyParams {
    /// The material: 1-based index into the `--brdf` menu.
    pub material: usize,
    /// The eye, in world units.
    pub eye: [f64; 3],
}

/// Largest magnitude of an area light's centre coordinate, side or
/// intensity.
pub const MAX_AREA_VALUE: f64 = 1e6;

/// An area light in the file's light plane (`ax`, `ay`, `aw`, `ah`, `ai`,
/// and optionally `aq` or `ad`, and `at`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaParams {
    /// Centre in the plane's coordinates (`ax`, `ay`).
    pub center: [f64; 2],
    /// Sides along the plane's axes before turning (`aw`, `ah`), > 0.
    pub size: [f64; 2],
    /// Radiance scale (`ai`), >= 0.
    pub intensity: f64,
    /// Turn in degrees, counter-clockwise seen from the lit side: `ad`
    /// (any finite angle within ±3600), or 90 × `aq` (quarter turns,
    /// 0..=3).
    pub degrees: f64,
    /// Index into the offered textures (`at`).
    pub texture: usize,
}

/// Which client sent a frame request and where it is in its sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct Client {
    /// The page's random identifier (`[A-Za-z0-9]`, 1 to 32 characters).
    pub id: String,
    /// Increases with each request the page sends.
    pub seq: u64,
}

/// The lighting of a frame: map and rotation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Index into the map list.
    pub map: usize,
    /// The rotation of the map.
    pub rotation: Rotation,
}

/// A frame request.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameParams {
    /// Index into the file list.
    pub file: usize,
    /// Map and rotation.
    pub lighting: Lighting,
    /// Terms N (checked against the file when the frame is made).
    pub terms: usize,
    /// Priority of wavelet lights.
    pub weighting: Weighting,
    /// The sender, for latest-request-wins (absent: never stale).
    pub client: Option<Client>,
    /// How a rotated light not yet cached is resampled.
    pub resampling: Resampling,
    /// An area light added to the map's image (files with near-field rows).
    pub area: Option<AreaParams>,
    /// A glossy material added to a texture-space file's relit texture.
    pub glossy: Option<GlossyParams>,
}

/// How a frame's rotated light is resampled when it is not cached
/// (`light=exact|draft`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Resampling {
    /// [`ltm_relight::EnvMap::to_cubemap`]: exact, tens of milliseconds.
    Exact,
    /// [`ltm_relight::PrefilteredMap`]: approximate, about a millisecond at
    /// `n = 32`, for frames during a drag. An exact light already cached is
    /// used instead.
    Draft,
}

/// Splits a query string into decoded `name → value` pairs; a repeated or
/// unknown name, or a value that is not UTF-8, is an error.
pub fn parse_query(query: &str, allowed: &[&str]) -> Result<HashMap<String, String>, BadRequest> {
    let mut out = HashMap::new();
    for (k, v) in form_urlencoded::parse(query.as_bytes()) {
        if !allowed.contains(&k.as_ref()) {
            return Err(BadRequest(format!(
                "unknown parameter '{}' (valid: {})",
                truncate(&k),
                allowed.join(", ")
            )));
        }
        if out.insert(k.to_string(), v.to_string()).is_some() {
            return Err(BadRequest(format!("parameter '{k}' given twice")));
        }
    }
    Ok(out)
}

/// At most 40 characters of a value, for messages.
fn truncate(s: &str) -> String {
    let t: String = s.chars().take(40).collect();
    if t.len() < s.len() {
        format!("{t}…")
    } else {
        t
    }
}

/// An index `0..count` named `name`; required.
pub fn index(q: &HashMap<String, String>, name: &str, count: usize) -> Result<usize, BadRequest> {
    let s = q
        .get(name)
        .ok_or_else(|| BadRequest(format!("missing parameter '{name}'")))?;
    match s.parse::<usize>() {
        Ok(i) if i < count => Ok(i),
        _ => Err(BadRequest(format!(
            "{name} '{}' is out of range (valid: 0..={})",
            truncate(s),
            count.saturating_sub(1)
        ))),
    }
}

/// An angle in degrees; absent means 0.
fn angle(q: &HashMap<String, String>, name: &str) -> Result<f64, BadRequest> {
    let Some(s) = q.get(name) else {
        return Ok(0.0);
    };
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() <= MAX_ANGLE => Ok(v),
        _ => Err(BadRequest(format!(
            "{name} '{}' is out of range (valid: a finite number of degrees in -{MAX_ANGLE}..={MAX_ANGLE})",
            truncate(s)
        ))),
    }
}

/// Map index and rotation (`map`, `yaw`, `pitch`, `roll`).
pub fn lighting(q: &HashMap<String, String>, b: &Bounds) -> Result<Lighting, BadRequest> {
    Ok(Lighting {
        map: index(q, "map", b.maps)?,
        rotation: Rotation::new(angle(q, "yaw")?, angle(q, "pitch")?, angle(q, "roll")?),
    })
}

/// The names a frame request may carry.
pub const FRAME_PARAMS: &[&str] = &[
    "file",
    "map",
    "yaw",
    "pitch",
    "roll",
    "n",
    "weighting",
    "client",
    "seq",
    "light",
    "ax",
    "ay",
    "aw",
    "ah",
    "ai",
    "aq",
    "ad",
    "at",
    "brdf",
    "eye",
];

/// A finite number within ±[`MAX_AREA_VALUE`] above `low` (exclusive when
/// `strict`).
fn area_value(
    q: &HashMap<String, String>,
    name: &str,
    low: f64,
    strict: bool,
) -> Result<f64, BadRequest> {
    let s = &q[name];
    match s.parse::<f64>() {
        Ok(v)
            if v.is_finite() && v.abs() <= MAX_AREA_VALUE && (v > low || (!strict && v == low)) =>
        {
            Ok(v)
        }
        _ => {
            let lower = if strict { ">" } else { ">=" };
            Err(BadRequest(format!(
                "{name} '{}' is out of range (valid: finite, {lower} {low}, at most {MAX_AREA_VALUE:e} in magnitude)",
                truncate(s)
            )))
        }
    }
}

/// The largest `ad` accepted, in degrees.
pub const MAX_AREA_DEGREES: f64 = 3600.0;

/// The area light of a frame request: `ax`, `ay`, `aw`, `ah`, `ai` all or
/// none; `aq` (quarter turns, 0..=3) or `ad` (degrees), and `at`
/// (texture), only with them.
fn area(q: &HashMap<String, String>, b: &Bounds) -> Result<Option<AreaParams>, BadRequest> {
    let given = ["ax", "ay", "aw", "ah", "ai"].map(|k| q.contains_key(k));
    if !given.iter().any(|&g| g) {
        if ["aq", "ad", "at"].iter().any(|k| q.contains_key(*k)) {
            return Err(BadRequest(
                "aq, ad and at need an area light (ax, ay, aw, ah, ai)".into(),
            ));
        }
        return Ok(None);
    }
    if !given.iter().all(|&g| g) {
        return Err(BadRequest(
            "an area light needs all of ax, ay, aw, ah and ai".into(),
        ));
    }
    let quarter_turns = match q.get("aq").map(|s| s.parse::<u32>()) {
        None => 0,
        Some(Ok(t)) if t <= 3 => t,
        Some(_) => {
            return Err(BadRequest(format!(
                "aq '{}' is out of range (valid: 0..=3 quarter turns)",
                truncate(&q["aq"])
            )))
        }
    };
    let degrees = match (q.get("ad"), q.contains_key("aq")) {
        (None, _) => 90.0 * f64::from(quarter_turns),
        (Some(_), true) => return Err(BadRequest("give aq or ad, not both".into())),
        (Some(s), false) => match s.parse::<f64>() {
            Ok(v) if v.is_finite() && v.abs() <= MAX_AREA_DEGREES => v,
            _ => {
                return Err(BadRequest(format!(
                    "ad '{}' is out of range (valid: finite degrees, at most {MAX_AREA_DEGREES} in magnitude)",
                    truncate(s)
                )))
            }
        },
    };
    let texture = match q.contains_key("at") {
        true => index(q, "at", b.textures)?,
        false => 0,
    };
    Ok(Some(AreaParams {
        center: [
            area_value(q, "ax", -MAX_AREA_VALUE, false)?,
            area_value(q, "ay", -MAX_AREA_VALUE, false)?,
        ],
        size: [
            area_value(q, "aw", 0.0, true)?,
            area_value(q, "ah", 0.0, true)?,
        ],
        intensity: area_value(q, "ai", 0.0, false)?,
        degrees,
        texture,
    }))
}

/// The glossy material of a frame request: `brdf` (0, the default, is the
/// baked material alone; 1..=materials a `--brdf` entry) and, with a
/// material, `eye` (`x,y,z`, finite, at most [`MAX_EYE`] in magnitude).
fn glossy(q: &HashMap<String, String>, b: &Bounds) -> Result<Option<GlossyParams>, BadRequest> {
    let material = match q.contains_key("brdf") {
        true => index(q, "brdf", b.materials + 1)?,
        false => 0,
    };
    let Some(e) = q.get("eye") else {
        return match material {
            0 => Ok(None),
            _ => Err(BadRequest("brdf needs eye (x,y,z)".into())),
        };
    };
    if material == 0 {
        return Err(BadRequest(
            "eye needs a glossy material (brdf 1 or more)".into(),
        ));
    }
    let v: Option<Vec<f64>> = e.split(',').map(|t| t.trim().parse().ok()).collect();
    match v.as_deref() {
        Some(&[x, y, z])
            if [x, y, z]
                .iter()
                .all(|c| c.is_finite() && c.abs() <= MAX_EYE) =>
        {
            Ok(Some(GlossyParams {
                material,
                eye: [x, y, z],
            }))
        }
        _ => Err(BadRequest(format!(
            "eye '{}' is not x,y,z (three finite numbers, at most {MAX_EYE:e} in magnitude)",
            truncate(e)
        ))),
    }
}

/// Parses a frame request's query (`n` is checked against `max_terms`).
pub fn frame(
    query: &str,
    b: &Bounds,
    max_terms: &dyn Fn(usize) -> usize,
) -> Result<FrameParams, BadRequest> {
    let q = parse_query(query, FRAME_PARAMS)?;
    let file = index(&q, "file", b.files)?;
    let lighting = lighting(&q, b)?;
    let max = max_terms(file);
    let n = q
        .get("n")
        .ok_or_else(|| BadRequest("missing parameter 'n'".into()))?;
    let terms = match n.parse::<usize>() {
        Ok(t) if (1..=max).contains(&t) => t,
        _ => {
            return Err(BadRequest(format!(
                "n '{}' is out of range (valid: 1..={max} for file {file})",
                truncate(n)
            )))
        }
    };
    let weighting = match q.get("weighting") {
        None => Weighting::Unweighted,
        Some(w) => w.parse().map_err(|e: String| BadRequest(truncate(&e)))?,
    };
    let resampling = match q.get("light").map(String::as_str) {
        None | Some("exact") => Resampling::Exact,
        Some("draft") => Resampling::Draft,
        Some(other) => {
            return Err(BadRequest(format!(
                "light '{}' is not exact or draft",
                truncate(other)
            )))
        }
    };
    Ok(FrameParams {
        file,
        lighting,
        terms,
        weighting,
        client: client(&q)?,
        resampling,
        area: area(&q, b)?,
        glossy: glossy(&q, b)?,
    })
}

/// `client` and `seq`: both or neither.
fn client(q: &HashMap<String, String>) -> Result<Option<Client>, BadRequest> {
    match (q.get("client"), q.get("seq")) {
        (None, None) => Ok(None),
        (Some(id), Some(seq)) => {
            let ok = !id.is_empty()
                && id.len() <= MAX_CLIENT_ID
                && id.bytes().all(|c| c.is_ascii_alphanumeric());
            if !ok {
                return Err(BadRequest(format!(
                    "client '{}' is not 1 to {MAX_CLIENT_ID} letters and digits",
                    truncate(id)
                )));
            }
            let seq = seq.parse::<u64>().map_err(|_| {
                BadRequest(format!(
                    "seq '{}' is out of range (valid: 0..={})",
                    truncate(seq),
                    u64::MAX
                ))
            })?;
            Ok(Some(Client {
                id: id.clone(),
                seq,
            }))
        }
        _ => Err(BadRequest("client and seq go together".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const B: Bounds = Bounds {
        files: 2,
        maps: 3,
        textures: 2,
        materials: 2,
    };

    fn parse(q: &str) -> Result<FrameParams, BadRequest> {
        frame(q, &B, &|_| 100)
    }

    #[test]
    fn good_requests_parse() {
        let p = parse("file=1&map=2&yaw=30.5&pitch=-10&n=100&weighting=transport&client=ab1&seq=7")
            .unwrap();
        assert_eq!(p.file, 1);
        assert_eq!(p.lighting.map, 2);
        assert_eq!(p.lighting.rotation, Rotation::new(30.5, -10.0, 0.0));
        assert_eq!(p.terms, 100);
        assert_eq!(p.weighting, Weighting::Transport);
        assert_eq!(p.client.unwrap().seq, 7);
        assert_eq!(p.area, None);
        let p = parse("file=0&map=0&n=1&ax=-0.5&ay=0.25&aw=1&ah=0.5&ai=3&aq=1&at=1").unwrap();
        let a = p.area.unwrap();
        assert_eq!(
            (a.center, a.size, a.intensity),
            ([-0.5, 0.25], [1.0, 0.5], 3.0)
        );
        assert_eq!((a.degrees, a.texture), (90.0, 1));
        let p = parse("file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1&ai=1&ad=-37.5").unwrap();
        assert_eq!(p.area.unwrap().degrees, -37.5);
        assert_eq!(p.glossy, None);
        let p = parse("file=0&map=0&n=1&brdf=2&eye=0.5,-1e3,3").unwrap();
        let g = p.glossy.unwrap();
        assert_eq!((g.material, g.eye), (2, [0.5, -1e3, 3.0]));
        assert_eq!(parse("file=0&map=0&n=1&brdf=0").unwrap().glossy, None);
    }

    #[test]
    fn bad_values_are_refused_with_their_range() {
        for (q, needle) in [
            (
                "file=2&map=0&n=1",
                "file '2' is out of range (valid: 0..=1)",
            ),
            ("file=0&map=3&n=1", "map '3'"),
            ("file=0&map=0&n=0", "valid: 1..=100"),
            ("file=0&map=0&n=101", "n '101'"),
            ("file=0&map=0&n=1&yaw=NaN", "yaw 'NaN'"),
            ("file=0&map=0&n=1&pitch=inf", "pitch 'inf'"),
            ("file=0&map=0&n=1&roll=-1e300", "roll"),
            ("file=0&map=0&n=1&yaw=36001", "finite number of degrees"),
            ("file=0&map=0&n=1&weighting=x", "unknown weighting"),
            (
                "file=0&map=0&n=1&path=/etc/passwd",
                "unknown parameter 'path'",
            ),
            ("file=0&map=0&n=1&n=2", "given twice"),
            ("file=0&map=0&n=1&client=a%2Fb&seq=1", "letters and digits"),
            ("file=0&map=0&n=1&client=a", "go together"),
            ("file=-1&map=0&n=1", "file '-1'"),
            ("map=0&n=1", "missing parameter 'file'"),
            (
                "file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1",
                "all of ax, ay, aw, ah and ai",
            ),
            ("file=0&map=0&n=1&ax=0&ay=0&aw=0&ah=1&ai=1", "aw '0'"),
            ("file=0&map=0&n=1&ax=nan&ay=0&aw=1&ah=1&ai=1", "ax 'nan'"),
            ("file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1&ai=-1", "ai '-1'"),
            ("file=0&map=0&n=1&ax=0&ay=0&aw=1e7&ah=1&ai=1", "aw '1e7'"),
            ("file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1&ai=1&aq=4", "aq '4'"),
            ("file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1&ai=1&at=2", "at '2'"),
            ("file=0&map=0&n=1&aq=1", "need an area light"),
            ("file=0&map=0&n=1&ad=10", "need an area light"),
            (
                "file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1&ai=1&ad=nan",
                "ad 'nan'",
            ),
            (
                "file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1&ai=1&ad=4000",
                "ad '4000'",
            ),
            (
                "file=0&map=0&n=1&ax=0&ay=0&aw=1&ah=1&ai=1&ad=1&aq=1",
                "not both",
            ),
            (
                "file=0&map=0&n=1&brdf=3&eye=0,0,1",
                "brdf '3' is out of range (valid: 0..=2)",
            ),
            ("file=0&map=0&n=1&brdf=1", "brdf needs eye"),
            ("file=0&map=0&n=1&eye=0,0,1", "eye needs a glossy material"),
            (
                "file=0&map=0&n=1&brdf=0&eye=0,0,1",
                "eye needs a glossy material",
            ),
            ("file=0&map=0&n=1&brdf=1&eye=0,0", "eye '0,0' is not x,y,z"),
            ("file=0&map=0&n=1&brdf=1&eye=0,0,1,2", "is not x,y,z"),
            ("file=0&map=0&n=1&brdf=1&eye=0,0,nan", "is not x,y,z"),
            ("file=0&map=0&n=1&brdf=1&eye=0,0,2e6", "is not x,y,z"),
            ("file=0&map=0&n=1&brdf=1&eye=0,0,1x", "is not x,y,z"),
        ] {
            let e = parse(q).unwrap_err().0;
            assert!(e.contains(needle), "{q}: {e}");
        }
    }

    proptest! {
        /// Arbitrary query strings never panic, and whatever parses is in range.
        #[test]
        fn arbitrary_queries_never_panic(q in "[a-z=&%0-9.eE+\\-]{0,80}") {
            if let Ok(p) = parse(&q) {
                prop_assert!(p.file < 2 && p.lighting.map < 3 && (1..=100).contains(&p.terms));
                let r = p.lighting.rotation;
                prop_assert!([r.yaw, r.pitch, r.roll].iter().all(|a| a.is_finite() && a.abs() <= MAX_ANGLE));
                if let Some(g) = p.glossy {
                    prop_assert!((1..=2).contains(&g.material));
                    prop_assert!(g.eye.iter().all(|c| c.is_finite() && c.abs() <= MAX_EYE));
                }
            }
        }

        #[test]
        fn arbitrary_bytes_never_panic(q in any::<Vec<u8>>()) {
            let _ = parse(&String::from_utf8_lossy(&q));
        }
    }
}
