//! The parameters a server declares (`GetParameters General 3D 6D`): capture frequency,
//! labelled markers, 6DOF bodies. Parsed with a standard XML parser (roxmltree), looking only
//! for the elements the bridge needs, wherever the server puts them, as the protocol
//! documentation asks of clients; written by the simulator in the same layout as QTM.

use crate::wire::Version;

/// Element-count bound of a parameters document (roxmltree's node limit).
const MAX_NODES: u32 = 200_000;

/// What a server declares.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Parameters {
    /// The root element's version (`QTM_Parameters_Ver_1.25` -> 1.25), if it names one.
    pub version: Option<Version>,
    /// Capture frequency, Hz (`General/Frequency`).
    pub frequency_hz: Option<f64>,
    /// Labels of the labelled markers (`The_3D/Label/Name`), in stream order.
    pub labels: Vec<String>,
    /// Names of the 6DOF bodies (`The_6D/Body/Name`), in stream order.
    pub bodies: Vec<String>,
}

/// Parameters that cannot be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParamsError {
    /// Not well-formed XML.
    #[error("parameters XML is not well-formed: {0}")]
    Xml(String),
    /// The root is not a QTM parameters block.
    #[error("parameters XML root is <{0}>, not <QTM_Parameters_Ver_x.y>")]
    Root(String),
    /// A value cannot be read.
    #[error("parameters XML: {path} = {value:?} is not a {what}")]
    Value {
        /// Element path.
        path: &'static str,
        /// Its text.
        value: String,
        /// What it should be.
        what: &'static str,
    },
}

impl Parameters {
    /// Index of a marker label.
    pub fn label_index(&self, label: &str) -> Option<usize> {
        self.labels.iter().position(|l| l == label)
    }

    /// Index of a 6DOF body.
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b == name)
    }

    /// Parses a parameters document.
    pub fn parse(xml: &str) -> Result<Parameters, ParamsError> {
        let opt = roxmltree::ParsingOptions {
            allow_dtd: false,
            nodes_limit: MAX_NODES,
            ..Default::default()
        };
        let doc = roxmltree::Document::parse_with_options(xml, opt)
            .map_err(|e| ParamsError::Xml(e.to_string()))?;
        let root = doc.root_element();
        let name = root.tag_name().name();
        let Some(ver) = name.strip_prefix("QTM_Parameters_Ver_") else {
            return Err(ParamsError::Root(name.chars().take(64).collect()));
        };
        let mut p = Parameters {
            version: Version::parse(ver),
            ..Default::default()
        };
        let text = |n: roxmltree::Node| n.text().unwrap_or("").trim().to_string();
        for block in root.children().filter(|n| n.is_element()) {
            match block.tag_name().name() {
                "General" => {
                    if let Some(f) = child(block, "Frequency") {
                        let t = text(f);
                        let v: f64 = t.parse().map_err(|_| ParamsError::Value {
                            path: "General/Frequency",
                            value: t.chars().take(64).collect(),
                            what: "number",
                        })?;
                        if !(v.is_finite() && v > 0.0) {
                            return Err(ParamsError::Value {
                                path: "General/Frequency",
                                value: t,
                                what: "positive frequency",
                            });
                        }
                        p.frequency_hz = Some(v);
                    }
                }
                "The_3D" => {
                    for l in block.children().filter(|n| n.has_tag_name("Label")) {
                        p.labels
                            .push(child(l, "Name").map(text).unwrap_or_default());
                    }
                }
                "The_6D" => {
                    for b in block.children().filter(|n| n.has_tag_name("Body")) {
                        // <Body><Name>..</Name></Body> (1.21 and later); older servers put
                        // the name in a <Name> child as well, some as an attribute.
                        let name = child(b, "Name")
                            .map(text)
                            .or_else(|| b.attribute("Name").map(str::to_string))
                            .unwrap_or_default();
                        p.bodies.push(name);
                    }
                }
                _ => {}
            }
        }
        Ok(p)
    }

    /// The parameters document of a server speaking `version` (the simulator's reply to
    /// `GetParameters`; `blocks` selects General, 3D and 6D).
    pub fn to_xml(&self, version: Version, general: bool, the_3d: bool, the_6d: bool) -> String {
        let esc = |s: &str| {
            s.replace('&', "&amp;")
                .replace('<', "&lt;")
                .replace('>', "&gt;")
        };
        let mut x = format!("<QTM_Parameters_Ver_{version}>\n");
        if general {
            x.push_str(&format!(
                "  <General>\n    <Frequency>{}</Frequency>\n    <Capture_Time>0</Capture_Time>\n  \
                 </General>\n",
                self.frequency_hz.unwrap_or(100.0)
            ));
        }
        if the_3d {
            x.push_str(&format!(
                "  <The_3D>\n    <AxisUpwards>+Z</AxisUpwards>\n    <Labels>{}</Labels>\n",
                self.labels.len()
            ));
            for l in &self.labels {
                x.push_str(&format!(
                    "    <Label>\n      <Name>{}</Name>\n      <RGBColor>65280</RGBColor>\n    \
                     </Label>\n",
                    esc(l)
                ));
            }
            x.push_str("  </The_3D>\n");
        }
        if the_6d {
            x.push_str("  <The_6D>\n");
            for b in &self.bodies {
                x.push_str(&format!(
                    "    <Body>\n      <Name>{}</Name>\n      <Enabled>true</Enabled>\n    \
                     </Body>\n",
                    esc(b)
                ));
            }
            x.push_str("  </The_6D>\n");
        }
        x.push_str(&format!("</QTM_Parameters_Ver_{version}>"));
        x
    }
}

fn child<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    n.children().find(|c| c.is_element() && c.has_tag_name(tag))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_simulators_document_reads_back() {
        let p = Parameters {
            version: Some(Version::NEWEST),
            frequency_hz: Some(100.0),
            labels: vec!["B1".into(), "M<1>".into()],
            bodies: vec!["platform".into()],
        };
        let x = p.to_xml(Version::NEWEST, true, true, true);
        assert_eq!(Parameters::parse(&x).unwrap(), p);
        let only_3d = Parameters::parse(&p.to_xml(Version::NEWEST, false, true, false)).unwrap();
        assert_eq!((only_3d.frequency_hz, only_3d.bodies.len()), (None, 0));
    }

    #[test]
    fn garbage_and_wrong_roots_are_errors() {
        assert!(matches!(
            Parameters::parse("<QTM_Parameters_Ver_1.25><General>"),
            Err(ParamsError::Xml(_))
        ));
        assert!(matches!(
            Parameters::parse("<html/>"),
            Err(ParamsError::Root(_))
        ));
        assert!(matches!(
            Parameters::parse(
                "<QTM_Parameters_Ver_1.25><General><Frequency>fast</Frequency></General>\
                 </QTM_Parameters_Ver_1.25>"
            ),
            Err(ParamsError::Value { .. })
        ));
        assert!(Parameters::parse("").is_err());
    }
}
