// The scene area: procedural light fields from JSON scene specs (docs/scenes.md).
//   scene_spec.h    SceneSpec and its parts, strict JSON parsing, to_json
//   render.h        render_scene: the true light field, disparity map and the effects run
//   random_scene.h  random_scene: varied scenes for training data
#pragma once

#include "lfnet/scene/random_scene.h"
#include "lfnet/scene/render.h"
#include "lfnet/scene/scene_spec.h"
