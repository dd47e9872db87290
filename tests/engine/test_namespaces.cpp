// The engine's sub-namespaces follow its folders (docs/design-notes.md, "Source layout"): each
// folder's types live in ts::<folder>, and the older names ts::<type> still resolve to them
// (engine/core.hpp's Mesh, PointCloud, Pose, Error stay in ts).
#include "engine/database/database.hpp"
#include "engine/features/fpfh.hpp"
#include "engine/geometry/distance_field.hpp"
#include "engine/geometry/mesh.hpp"
#include "engine/recognition/answer_set.hpp"
#include "engine/recognition/pipeline/stage.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/touch/active_touch.hpp"

#include <type_traits>

// Checked when this file compiles (the engine tests' build): a folder's type outside its folder's
// namespace, or the older name no longer resolving, is a compile error here.
static_assert(std::is_same_v<ts::geometry::DistanceField, ts::DistanceField>);
static_assert(std::is_same_v<ts::geometry::MeshIndex, ts::MeshIndex>);
static_assert(std::is_same_v<ts::features::FpfhSettings, ts::FpfhSettings>);
static_assert(std::is_same_v<ts::database::Database, ts::Database>);
static_assert(std::is_same_v<ts::recognition::Recognizer, ts::Recognizer>);
static_assert(std::is_same_v<ts::recognition::AnswerSet, ts::AnswerSet>);
static_assert(std::is_same_v<ts::recognition::pipeline::Stage, ts::pipeline::Stage>);
static_assert(std::is_same_v<ts::touch::GraspPlanner, ts::GraspPlanner>);
