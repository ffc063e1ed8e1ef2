//! Loading OpenCV Haar cascade XML files into a flat, validated [`Cascade`].
//!
//! Two layouts are accepted:
//!
//! * the "new" format written by `opencv_traincascade` and shipped with OpenCV 3/4
//!   (`<cascade type_id="opencv-cascade-classifier">`, `stageType` BOOST, `featureType` HAAR,
//!   trees as `internalNodes` + `leafValues`, features in a separate list);
//! * the "old" format of `opencv_haartraining` (`type_id="opencv-haar-classifier"`: each tree
//!   node carries its own feature and `left_val`/`left_node` children). OpenCV 4 converts such a
//!   file to the new layout when loading it; we do the same conversion here. Stage trees
//!   (`parent`/`next` links) are read as the plain chain of stages, as that conversion does.
//!
//! Everything read from the file is checked (indices in range, finite numbers, rectangles inside
//! the window, trees that terminate), so evaluation never needs bounds checks or can loop forever.

use std::path::Path;
use std::sync::{Arc, OnceLock};

use roxmltree::{Document, Node};

use crate::{Error, Result};

/// The embedded default cascade (OpenCV's `haarcascade_frontalface_alt2.xml`, Intel licence header
/// kept in the file).
const FRONTAL_FACE_ALT2_XML: &str = include_str!("../../models/haarcascade_frontalface_alt2.xml");

/// The embedded second cascade (OpenCV's `haarcascade_frontalface_default.xml`, Intel licence
/// header kept in the file): the pipeline's optional fallback when alt2 finds no usable face.
const FRONTAL_FACE_DEFAULT_XML: &str =
    include_str!("../../models/haarcascade_frontalface_default.xml");

/// OpenCV lowers every stage threshold by this much (`THRESHOLD_EPS` in cascadedetect.cpp) so a
/// window scoring exactly the trained threshold passes despite rounding; we copy it to agree.
const THRESHOLD_EPS: f32 = 1e-5;

/// OpenCV's `HaarEvaluator::Feature` has room for three rectangles.
const MAX_RECTS: usize = 3;

/// One weighted rectangle of a Haar feature, in window pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HaarRect {
    pub(crate) x: i32,
    pub(crate) y: i32,
    pub(crate) w: i32,
    pub(crate) h: i32,
    pub(crate) weight: f32,
}

/// A Haar-like feature: up to three weighted rectangles, upright or rotated by 45°.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Feature {
    /// Unused slots have weight 0 and an empty rectangle, as in OpenCV.
    pub(crate) rects: [HaarRect; MAX_RECTS],
    pub(crate) tilted: bool,
}

/// An internal tree node: `value < threshold` goes left. A child `> 0` is a node index within
/// the same tree, a child `<= 0` is the leaf `-child` of that tree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TreeNode {
    pub(crate) left: i32,
    pub(crate) right: i32,
    pub(crate) feature: u32,
    pub(crate) threshold: f32,
}

/// The shape all of a cascade's trees share, if any.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TreeShape {
    /// One node each (a stump), as in `haarcascade_frontalface_default.xml`. Walked node by
    /// node like [`TreeShape::Mixed`] (a stump's walk has no second branch to save).
    Stumps,
    /// Two nodes each: a root with one leaf and one node child (node 1 of the tree), whose
    /// children are both leaves, as in `haarcascade_frontalface_alt2.xml`.
    RootAndOneChild,
    /// Anything else: walked node by node.
    Mixed,
}

/// One weak classifier: a run of nodes and a run of leaves in the cascade's flat arrays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Tree {
    pub(crate) first_node: u32,
    pub(crate) first_leaf: u32,
}

/// One boosting stage: a run of trees and the threshold their summed leaves must reach.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Stage {
    pub(crate) first_tree: u32,
    pub(crate) tree_count: u32,
    /// Already lowered by [`THRESHOLD_EPS`].
    pub(crate) threshold: f32,
}

/// The flat arrays of a parsed cascade.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CascadeData {
    pub(crate) window: (u32, u32),
    pub(crate) stages: Vec<Stage>,
    pub(crate) trees: Vec<Tree>,
    pub(crate) nodes: Vec<TreeNode>,
    pub(crate) leaves: Vec<f32>,
    pub(crate) features: Vec<Feature>,
    /// How every tree is shaped: [`TreeShape::RootAndOneChild`] trees are scored without
    /// branches.
    pub(crate) shape: TreeShape,
    pub(crate) has_tilted: bool,
}

/// A boosted cascade of Haar-feature trees, as trained by OpenCV.
///
/// Cheap to clone (the arrays are shared).
#[derive(Debug, Clone, PartialEq)]
pub struct Cascade {
    pub(crate) data: Arc<CascadeData>,
}

fn err<T>(msg: impl Into<String>) -> Result<T> {
    Err(Error::Cascade(msg.into()))
}

impl Cascade {
    /// OpenCV's `haarcascade_frontalface_alt2.xml`, embedded in the library.
    ///
    /// Parsed once per process; later calls clone a shared handle.
    pub fn frontal_face_alt2() -> Cascade {
        static CELL: OnceLock<Cascade> = OnceLock::new();
        Self::embedded(&CELL, FRONTAL_FACE_ALT2_XML)
    }

    /// OpenCV's `haarcascade_frontalface_default.xml` (Viola and Jones's stump cascade, 25
    /// stages), embedded in the library. It fires on some faces that alt2 misses (rolled, partly
    /// covered) and on more non-faces, so the pipeline asks it only on request
    /// (the quick search's fallback cascade). Parsed once per process.
    pub(crate) fn frontal_face_default() -> Cascade {
        static CELL: OnceLock<Cascade> = OnceLock::new();
        Self::embedded(&CELL, FRONTAL_FACE_DEFAULT_XML)
    }

    /// The embedded cascade `xml`, parsed on first use into `cell`.
    fn embedded(cell: &'static OnceLock<Cascade>, xml: &str) -> Cascade {
        cell.get_or_init(|| match Cascade::from_xml(xml) {
            Ok(c) => c,
            // The embedded files are fixed at compile time and covered by the tests, so this
            // cannot happen in a released build.
            Err(e) => unreachable!("embedded cascade is invalid: {e}"),
        })
        .clone()
    }

    /// Parse a cascade from the text of an OpenCV cascade XML file.
    pub fn from_xml(xml: &str) -> Result<Cascade> {
        let doc = Document::parse(xml).map_err(|e| Error::Cascade(format!("not XML: {e}")))?;
        let root = doc.root_element();
        if root.tag_name().name() != "opencv_storage" {
            return err(format!(
                "root element is <{}>, expected <opencv_storage>",
                root.tag_name().name()
            ));
        }
        let Some(top) = root.children().find(|n| n.is_element()) else {
            return err("<opencv_storage> is empty");
        };
        let data = match top.attribute("type_id") {
            Some("opencv-cascade-classifier") => parse_new(top)?,
            Some("opencv-haar-classifier") => parse_old(top)?,
            // Files written without a type_id still use the new layout when they have <stages>
            // next to <featureType>.
            None if child(top, "featureType").is_some() => parse_new(top)?,
            other => {
                return err(format!(
                    "unknown cascade type {:?} (expected opencv-cascade-classifier or opencv-haar-classifier)",
                    other.unwrap_or("<none>")
                ))
            }
        };
        Ok(Cascade {
            data: Arc::new(data),
        })
    }

    /// Read and parse a cascade XML file.
    pub fn from_file(path: &Path) -> Result<Cascade> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Cascade::from_xml(&text)
            .map_err(|e| Error::Cascade(format!("{}: {}", path.display(), strip_prefix(&e))))
    }

    /// The training window `(width, height)` in pixels (20×20 for the frontal-face cascades).
    #[cfg(test)]
    pub(crate) fn window_size(&self) -> (u32, u32) {
        self.data.window
    }

    /// Number of boosting stages.
    #[cfg(test)]
    pub(crate) fn stage_count(&self) -> usize {
        self.data.stages.len()
    }

    /// Number of weak classifiers (trees) over all stages.
    #[cfg(test)]
    pub(crate) fn tree_count(&self) -> usize {
        self.data.trees.len()
    }

    /// Number of distinct Haar features.
    #[cfg(test)]
    pub(crate) fn feature_count(&self) -> usize {
        self.data.features.len()
    }

    /// Whether any feature is rotated by 45° (needs the tilted integral image).
    #[cfg(test)]
    pub(crate) fn has_tilted_features(&self) -> bool {
        self.data.has_tilted
    }
}

/// The message of a cascade error without its `cascade: ` display prefix.
fn strip_prefix(e: &Error) -> String {
    match e {
        Error::Cascade(m) => m.clone(),
        other => other.to_string(),
    }
}

fn child<'a, 'i>(n: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    n.children()
        .find(|c| c.is_element() && c.tag_name().name() == name)
}

fn need<'a, 'i>(n: Node<'a, 'i>, name: &str, ctx: &str) -> Result<Node<'a, 'i>> {
    child(n, name).ok_or_else(|| Error::Cascade(format!("{ctx}: missing <{name}>")))
}

/// The element children of a sequence node (`<_>` items).
fn items<'a, 'i>(n: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    n.children().filter(|c| c.is_element())
}

/// All text of an element (comments skipped), whitespace-separated tokens.
fn text_of(n: Node) -> String {
    let mut s = String::new();
    for c in n.children().filter(|c| c.is_text()) {
        s.push_str(c.text().unwrap_or(""));
        s.push(' ');
    }
    s
}

fn numbers(n: Node, ctx: &str) -> Result<Vec<f64>> {
    text_of(n)
        .split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| Error::Cascade(format!("{ctx}: {t:?} is not a number")))
        })
        .collect()
}

fn number(n: Node, ctx: &str) -> Result<f64> {
    match numbers(n, ctx)?.as_slice() {
        [v] => Ok(*v),
        v => err(format!("{ctx}: expected one number, found {}", v.len())),
    }
}

fn finite_f32(v: f64, ctx: &str) -> Result<f32> {
    let f = v as f32;
    if f.is_finite() {
        Ok(f)
    } else {
        err(format!("{ctx}: value {v} is not a finite 32-bit float"))
    }
}

/// An integer-valued number in `lo..=hi`.
fn int_in(v: f64, lo: i64, hi: i64, ctx: &str) -> Result<i64> {
    if v.fract() != 0.0 || !v.is_finite() || v < lo as f64 || v > hi as f64 {
        return err(format!("{ctx}: {v} is not an integer in {lo}..={hi}"));
    }
    Ok(v as i64)
}

fn window_dim(v: f64, what: &str) -> Result<u32> {
    // OpenCV's variance window is (1, 1, w-2, h-2): anything under 3 pixels has no interior.
    Ok(int_in(v, 3, 4096, &format!("window {what}"))? as u32)
}

/// `<rects>` of a feature: 1 to 3 items "x y w h weight".
fn parse_feature(f: Node, window: (u32, u32), ctx: &str) -> Result<Feature> {
    let rects_node = need(f, "rects", ctx)?;
    let tilted = match child(f, "tilted") {
        Some(t) => number(t, ctx)? != 0.0,
        None => false,
    };
    let empty = HaarRect {
        x: 0,
        y: 0,
        w: 0,
        h: 0,
        weight: 0.0,
    };
    let mut rects = [empty; MAX_RECTS];
    let mut count = 0;
    for (i, r) in items(rects_node).enumerate() {
        let rctx = format!("{ctx} rect {i}");
        if i >= MAX_RECTS {
            return err(format!("{ctx}: more than {MAX_RECTS} rectangles"));
        }
        let v = numbers(r, &rctx)?;
        let [x, y, w, h, weight] = v.as_slice() else {
            return err(format!(
                "{rctx}: expected 5 numbers \"x y w h weight\", found {}",
                v.len()
            ));
        };
        let (ww, wh) = (i64::from(window.0), i64::from(window.1));
        let x = int_in(*x, 0, ww, &rctx)?;
        let y = int_in(*y, 0, wh, &rctx)?;
        let w = int_in(*w, 0, ww, &rctx)?;
        let h = int_in(*h, 0, wh, &rctx)?;
        // Every corner the evaluator reads must lie inside the window's integral image.
        let inside = if tilted {
            // A 45° rectangle spans x-h ..= x+w horizontally and y ..= y+w+h vertically.
            x - h >= 0 && x + w <= ww && y + w + h <= wh
        } else {
            x + w <= ww && y + h <= wh
        };
        if !inside {
            return err(format!(
                "{rctx}: rectangle ({x}, {y}, {w}, {h}) leaves the {ww}x{wh} window"
            ));
        }
        rects[i] = HaarRect {
            x: x as i32,
            y: y as i32,
            w: w as i32,
            h: h as i32,
            weight: finite_f32(*weight, &rctx)?,
        };
        count += 1;
    }
    if count == 0 {
        return err(format!("{ctx}: feature has no rectangles"));
    }
    Ok(Feature { rects, tilted })
}

/// Check a tree's child links: node children point forward (so evaluation terminates), leaf
/// children name an existing leaf, features exist.
fn check_tree(
    nodes: &[TreeNode],
    leaf_count: usize,
    feature_count: usize,
    ctx: &str,
) -> Result<()> {
    if nodes.is_empty() {
        return err(format!("{ctx}: tree has no nodes"));
    }
    for (i, n) in nodes.iter().enumerate() {
        for c in [n.left, n.right] {
            if c > 0 {
                if c as usize <= i || c as usize >= nodes.len() {
                    return err(format!(
                        "{ctx}: node {i} links to node {c} (tree has {} nodes; links must point forward)",
                        nodes.len()
                    ));
                }
            } else if c.unsigned_abs() as usize >= leaf_count {
                return err(format!(
                    "{ctx}: node {i} links to leaf {} (tree has {leaf_count} leaves)",
                    -c
                ));
            }
        }
        if n.feature as usize >= feature_count {
            return err(format!(
                "{ctx}: node {i} uses feature {} of {feature_count}",
                n.feature
            ));
        }
    }
    Ok(())
}

fn finish(
    window: (u32, u32),
    stages: Vec<Stage>,
    trees: Vec<Tree>,
    nodes: Vec<TreeNode>,
    leaves: Vec<f32>,
    features: Vec<Feature>,
) -> Result<CascadeData> {
    if stages.is_empty() {
        return err("cascade has no stages");
    }
    // Each tree's nodes (trees are validated, so these runs are inside `nodes`).
    let tree_nodes = |i: usize, t: &Tree| {
        let end = trees
            .get(i + 1)
            .map_or(nodes.len(), |n| n.first_node as usize);
        nodes.get(t.first_node as usize..end).unwrap_or(&[])
    };
    let is_leaf = |child: i32| child <= 0;
    let shape = if trees
        .iter()
        .enumerate()
        .all(|(i, t)| tree_nodes(i, t).len() == 1)
    {
        TreeShape::Stumps
    } else if trees
        .iter()
        .enumerate()
        .all(|(i, t)| match tree_nodes(i, t) {
            [root, child] => {
                ((is_leaf(root.left) && root.right == 1) || (root.left == 1 && is_leaf(root.right)))
                    && is_leaf(child.left)
                    && is_leaf(child.right)
            }
            _ => false,
        })
    {
        TreeShape::RootAndOneChild
    } else {
        TreeShape::Mixed
    };
    let has_tilted = features.iter().any(|f| f.tilted);
    Ok(CascadeData {
        window,
        stages,
        trees,
        nodes,
        leaves,
        features,
        shape,
        has_tilted,
    })
}

fn parse_new(top: Node) -> Result<CascadeData> {
    let ctx = "cascade";
    let stage_type = text_of(need(top, "stageType", ctx)?);
    if stage_type.trim() != "BOOST" {
        return err(format!(
            "stageType {:?} not supported (only BOOST)",
            stage_type.trim()
        ));
    }
    let feature_type = text_of(need(top, "featureType", ctx)?);
    if feature_type.trim() != "HAAR" {
        return err(format!(
            "featureType {:?} not supported (only HAAR)",
            feature_type.trim()
        ));
    }
    let width = window_dim(number(need(top, "width", ctx)?, "width")?, "width")?;
    let height = window_dim(number(need(top, "height", ctx)?, "height")?, "height")?;
    let window = (width, height);
    if let Some(fp) = child(top, "featureParams") {
        if let Some(m) = child(fp, "maxCatCount") {
            if number(m, "maxCatCount")? != 0.0 {
                return err("categorical (maxCatCount > 0) cascades are not supported");
            }
        }
    }

    let features = items(need(top, "features", ctx)?)
        .enumerate()
        .map(|(i, f)| parse_feature(f, window, &format!("feature {i}")))
        .collect::<Result<Vec<_>>>()?;

    let mut stages = Vec::new();
    let mut trees = Vec::new();
    let mut nodes = Vec::new();
    let mut leaves = Vec::new();
    for (si, s) in items(need(top, "stages", ctx)?).enumerate() {
        let sctx = format!("stage {si}");
        let threshold =
            finite_f32(number(need(s, "stageThreshold", &sctx)?, &sctx)?, &sctx)? - THRESHOLD_EPS;
        let first_tree = trees.len() as u32;
        for (wi, w) in items(need(s, "weakClassifiers", &sctx)?).enumerate() {
            let wctx = format!("{sctx} tree {wi}");
            let inner = numbers(need(w, "internalNodes", &wctx)?, &wctx)?;
            let leaf_values = numbers(need(w, "leafValues", &wctx)?, &wctx)?;
            if inner.is_empty() || inner.len() % 4 != 0 {
                return err(format!(
                    "{wctx}: internalNodes has {} numbers, expected groups of 4 \"left right feature threshold\"",
                    inner.len()
                ));
            }
            let tree_nodes = inner
                .chunks_exact(4)
                .map(|c| {
                    Ok(TreeNode {
                        left: int_in(c[0], -(1 << 20), 1 << 20, &wctx)? as i32,
                        right: int_in(c[1], -(1 << 20), 1 << 20, &wctx)? as i32,
                        feature: int_in(c[2], 0, u32::MAX.into(), &wctx)? as u32,
                        threshold: finite_f32(c[3], &wctx)?,
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            check_tree(&tree_nodes, leaf_values.len(), features.len(), &wctx)?;
            trees.push(Tree {
                first_node: nodes.len() as u32,
                first_leaf: leaves.len() as u32,
            });
            nodes.extend(tree_nodes);
            for v in leaf_values {
                leaves.push(finite_f32(v, &wctx)?);
            }
        }
        let tree_count = trees.len() as u32 - first_tree;
        if tree_count == 0 {
            return err(format!("{sctx}: no weak classifiers"));
        }
        stages.push(Stage {
            first_tree,
            tree_count,
            threshold,
        });
    }
    finish(window, stages, trees, nodes, leaves, features)
}

/// The old `opencv-haar-classifier` layout, converted the way OpenCV 4's loader converts it:
/// one new feature per tree node, leaves numbered in reading order.
fn parse_old(top: Node) -> Result<CascadeData> {
    let ctx = "old-format cascade";
    let size = numbers(need(top, "size", ctx)?, "size")?;
    let [w, h] = size.as_slice() else {
        return err("size: expected \"width height\"");
    };
    let window = (window_dim(*w, "width")?, window_dim(*h, "height")?);

    let mut stages = Vec::new();
    let mut trees = Vec::new();
    let mut nodes = Vec::new();
    let mut leaves = Vec::new();
    let mut features = Vec::new();
    for (si, s) in items(need(top, "stages", ctx)?).enumerate() {
        let sctx = format!("stage {si}");
        let threshold =
            finite_f32(number(need(s, "stage_threshold", &sctx)?, &sctx)?, &sctx)? - THRESHOLD_EPS;
        let first_tree = trees.len() as u32;
        for (ti, t) in items(need(s, "trees", &sctx)?).enumerate() {
            let tctx = format!("{sctx} tree {ti}");
            let raw: Vec<Node> = items(t).collect();
            let mut tree_nodes = Vec::with_capacity(raw.len());
            let mut tree_leaves = Vec::new();
            for (ni, n) in raw.iter().enumerate() {
                let nctx = format!("{tctx} node {ni}");
                let feature = parse_feature(need(*n, "feature", &nctx)?, window, &nctx)?;
                let threshold = finite_f32(number(need(*n, "threshold", &nctx)?, &nctx)?, &nctx)?;
                let mut link = |val: &str, node: &str| -> Result<i32> {
                    if let Some(v) = child(*n, val) {
                        let leaf = tree_leaves.len() as i32;
                        tree_leaves.push(finite_f32(number(v, &nctx)?, &nctx)?);
                        Ok(-leaf)
                    } else if let Some(v) = child(*n, node) {
                        Ok(int_in(number(v, &nctx)?, 1, raw.len() as i64, &nctx)? as i32)
                    } else {
                        err(format!("{nctx}: needs <{val}> or <{node}>"))
                    }
                };
                let left = link("left_val", "left_node")?;
                let right = link("right_val", "right_node")?;
                tree_nodes.push(TreeNode {
                    left,
                    right,
                    feature: features.len() as u32,
                    threshold,
                });
                features.push(feature);
            }
            check_tree(&tree_nodes, tree_leaves.len(), features.len(), &tctx)?;
            trees.push(Tree {
                first_node: nodes.len() as u32,
                first_leaf: leaves.len() as u32,
            });
            nodes.extend(tree_nodes);
            leaves.extend(tree_leaves);
        }
        let tree_count = trees.len() as u32 - first_tree;
        if tree_count == 0 {
            return err(format!("{sctx}: no trees"));
        }
        stages.push(Stage {
            first_tree,
            tree_count,
            threshold,
        });
    }
    finish(window, stages, trees, nodes, leaves, features)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A one-stage, one-stump cascade on a 4x4 window: the left half minus the right half.
    pub(crate) const TINY: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<cascade type_id="opencv-cascade-classifier"><stageType>BOOST</stageType>
  <featureType>HAAR</featureType>
  <height>4</height>
  <width>4</width>
  <stageParams><maxWeakCount>1</maxWeakCount></stageParams>
  <featureParams><maxCatCount>0</maxCatCount></featureParams>
  <stageNum>1</stageNum>
  <stages>
    <_>
      <maxWeakCount>1</maxWeakCount>
      <stageThreshold>0.5</stageThreshold>
      <weakClassifiers>
        <_>
          <internalNodes>0 -1 0 0.25</internalNodes>
          <leafValues>0 1</leafValues></_></weakClassifiers></_></stages>
  <features>
    <_>
      <rects>
        <_>0 0 2 4 1.</_>
        <_>2 0 2 4 -1.</_></rects>
      <tilted>0</tilted></_></features></cascade>
</opencv_storage>
"#;

    fn cascade_err(xml: &str) -> String {
        match Cascade::from_xml(xml) {
            Err(Error::Cascade(m)) => m,
            Err(e) => panic!("wrong error kind: {e}"),
            Ok(_) => panic!("malformed cascade accepted"),
        }
    }

    #[test]
    fn parses_embedded_alt2() {
        let c = Cascade::frontal_face_alt2();
        assert_eq!(c.window_size(), (20, 20));
        assert_eq!(c.stage_count(), 20);
        assert!(!c.has_tilted_features());
        // alt2 uses depth-2 trees: 2 nodes and 3 leaves each.
        assert_eq!(c.data.shape, TreeShape::RootAndOneChild);
        assert_eq!(c.data.nodes.len(), 2 * c.tree_count());
        assert_eq!(c.data.leaves.len(), 3 * c.tree_count());
        assert_eq!(c.feature_count(), c.data.nodes.len());
        assert_eq!(c.data.stages[0].tree_count, 3);
        assert!((c.data.stages[0].threshold - (0.350_692_3 - 1e-5)).abs() < 1e-6);
        // Parsed once: a second call shares the arrays.
        assert!(Arc::ptr_eq(&c.data, &Cascade::frontal_face_alt2().data));
    }

    #[test]
    fn parses_embedded_default() {
        let c = Cascade::frontal_face_default();
        assert_eq!(c.window_size(), (24, 24));
        assert_eq!(c.stage_count(), 25);
        assert_eq!(c.data.shape, TreeShape::Stumps);
        assert!(Arc::ptr_eq(&c.data, &Cascade::frontal_face_default().data));
    }

    #[test]
    fn parses_tiny_cascade() {
        let c = Cascade::from_xml(TINY).unwrap();
        assert_eq!(c.window_size(), (4, 4));
        assert_eq!(
            (c.stage_count(), c.tree_count(), c.feature_count()),
            (1, 1, 1)
        );
        assert_eq!(c.data.shape, TreeShape::Stumps);
        assert_eq!(c.data.nodes[0].left, 0);
        assert_eq!(c.data.nodes[0].right, -1);
        assert_eq!(c.data.features[0].rects[1].weight, -1.0);
        assert_eq!(c.data.features[0].rects[2].weight, 0.0);
    }

    #[test]
    fn parses_old_format() {
        let xml = r#"<opencv_storage><old type_id="opencv-haar-classifier">
  <size>4 4</size>
  <stages><_>
    <trees><_>
      <_><feature><rects><_>0 0 2 4 1.</_><_>2 0 2 4 -1.</_></rects><tilted>0</tilted></feature>
         <threshold>0.25</threshold><left_val>0</left_val><right_node>1</right_node></_>
      <_><feature><rects><_>0 0 4 2 1.</_></rects><tilted>0</tilted></feature>
         <threshold>0.1</threshold><left_val>0.5</left_val><right_val>1</right_val></_>
    </_></trees>
    <stage_threshold>0.5</stage_threshold><parent>-1</parent><next>-1</next></_></stages>
</old></opencv_storage>"#;
        let c = Cascade::from_xml(xml).unwrap();
        assert_eq!(
            (c.stage_count(), c.tree_count(), c.feature_count()),
            (1, 1, 2)
        );
        let n = &c.data.nodes;
        assert_eq!((n[0].left, n[0].right, n[0].feature), (0, 1, 0));
        assert_eq!((n[1].left, n[1].right, n[1].feature), (-1, -2, 1));
        assert_eq!(c.data.leaves, vec![0.0, 0.5, 1.0]);
    }

    #[test]
    fn system_cascades_parse_if_present() {
        let dir = Path::new("/usr/share/opencv4/haarcascades");
        let Ok(entries) = std::fs::read_dir(dir) else {
            // Past the test harness's output capture, so the skip shows.
            let note = format!("skipped: {} not found\n", dir.display());
            let _ = std::io::Write::write_all(&mut std::io::stderr(), note.as_bytes());
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "xml") {
                let c = Cascade::from_file(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                assert!(c.stage_count() > 0);
            }
        }
    }

    #[test]
    fn malformed_files_are_errors() {
        assert!(cascade_err("not xml <<<").contains("not XML"));
        assert!(cascade_err("<foo/>").contains("opencv_storage"));
        assert!(cascade_err("<opencv_storage/>").contains("empty"));
        let bad = |from: &str, to: &str| {
            assert!(TINY.contains(from), "{from}");
            cascade_err(&TINY.replacen(from, to, 1))
        };
        assert!(bad("0 -1 0 0.25", "0 -1 7 0.25").contains("feature 7"));
        assert!(bad("0 -1 0 0.25", "0 -5 0 0.25").contains("leaf 5"));
        assert!(bad("0 -1 0 0.25", "1 -1 0 0.25").contains("forward"));
        assert!(bad("0 -1 0 0.25", "0 -1 0 nan").contains("finite"));
        assert!(bad("0 -1 0 0.25", "0 -1 0").contains("groups of 4"));
        assert!(bad("0 -1 0 0.25", "0 -1 0 abc").contains("not a number"));
        assert!(bad("<width>4</width>", "<width>0</width>").contains("width"));
        assert!(bad("<height>4</height>", "").contains("height"));
        assert!(bad("2 0 2 4 -1.", "3 0 2 4 -1.").contains("leaves"));
        assert!(bad("2 0 2 4 -1.", "2 0 2 -1.").contains("5 numbers"));
        assert!(bad("<tilted>0</tilted>", "<tilted>1</tilted>").contains("leaves"));
        assert!(bad("HAAR", "LBP").contains("LBP"));
        assert!(bad("<stageThreshold>0.5", "<stageThreshold>inf").contains("finite"));
        assert!(bad("opencv-cascade-classifier", "something-else").contains("unknown"));
        assert!(bad("<leafValues>0 1</leafValues>", "").contains("leafValues"));
    }
}
