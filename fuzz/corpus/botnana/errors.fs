1 0 /
: half if 1 ;
nosuchword
1 +
." unterminated
;deploy
9 3 drive-on
