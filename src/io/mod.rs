//! Scene loaders: COLLADA (`.dae`, CS184 dialect), OBJ and PLY. Each returns a
//! [`crate::SceneBuilder`] or a [`LoadError`] naming the file and the element or line.
